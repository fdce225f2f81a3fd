"""A trial of a study's search (rss6 budget's sweep of clearance scales, rss6 allocate's greedy
search of fit classes): one ensemble run at one candidate and judged by the requirement specs."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from ..analysis.gate import Verdict, judge_all
from ..ensemble.run import EnsembleSpec, ensemble

__all__ = ["Trial", "run_trial"]


@dataclass(frozen=True)
class Trial:
    """One ensemble of a search: the candidate it tried (a clearance scale factor for the budget, a
    class per joint family for the allocation), its file and the specs' verdicts there."""
    candidate: object
    path: Path | None
    verdicts: tuple[Verdict, ...]

    @property
    def passed(self) -> bool:
        return all(v.outcome == "pass" for v in self.verdicts)


def run_trial(spec: EnsembleSpec, scene_text: str, candidate, specs, n: int, path: Path, confidence: float,
              workers: int) -> Trial:
    """Run (or resume) the n-realisation ensemble of ``spec`` with the scene ``scene_text`` (the
    candidate's) into ``path`` and judge ``specs`` on it at ``confidence``."""
    outcome = ensemble(replace(spec, scene_text=scene_text), n, path, workers=workers, progress=False)
    verdicts = tuple(judge_all(specs, outcome.dataset, confidence))
    outcome.dataset.close()   # a search runs many trials in one process: each file is let go once judged
    return Trial(candidate, path, verdicts)
