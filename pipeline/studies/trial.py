"""A trial of a study's search (rss6 budget's sweep of clearance scales, rss6 allocate's greedy
search of fit classes): one ensemble run at one candidate and judged by the requirement specs."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from ..analysis.gate import Verdict, judge_all
from ..ensemble.run import EnsembleSpec, ensemble
from ..vocabulary import CONFIDENCE

__all__ = ["Trial", "run_trial", "SELECTION_NOTE", "fresh_check_command"]

# a search's answer is judged on the draws that chose it (the seed's realisations 0..n-1): picking the
# cheapest or largest passing candidate selects for lucky draws, so that verdict checks the search, not the choice
SELECTION_NOTE = ("the {what} uses the draws that chose the answer (same seed, realisations 0..n-1), so "
                  "its bounds are optimistic for the answer")


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


def fresh_check_command(scene_path: Path, model: str, n: int, seed: int, specs: list[str],
                        confidence: float = CONFIDENCE) -> str:
    """The shell-quoted `rss6 run` that judges a search's answer scene on draws it did not see (the next
    seed); at another confidence than the gate's default, `rss6 stats` judges the file at that one."""
    from shlex import quote
    output = quote(f"{scene_path.with_suffix('')}_seed{seed + 1}.nc")
    requires = " ".join(f"--require {quote(s)}" for s in specs)
    run = f"rss6 run {quote(str(scene_path))} --model {model} -n {n} --seed {seed + 1} -o {output}"
    if confidence == CONFIDENCE:
        return f"{run} {requires}"
    return f"{run} && rss6 stats {output} --confidence {confidence:g} {requires}"
