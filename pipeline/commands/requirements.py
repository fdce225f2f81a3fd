"""--require for rss6 run and rss6 stats: the specs parsed before any work, judged on a Dataset,
and written into a file's attributes."""
from __future__ import annotations

import json

from ..vocabulary import CONFIDENCE, STEP_WORDS, WINDOWS, OptionError, step_measured


def requirements(args) -> list:
    """The --require specs; a malformed one raises SpecError (one line)."""
    from ..analysis.spec import parse_specs
    if args.undecided is not None and not args.require:
        raise OptionError(f"--undecided {args.undecided}: applies with --require only")
    return parse_specs(args.require)


def known_windows(specs: list, scene=None, flag: str | None = None) -> None:
    """A --require or --until (or ``flag``'s specs or events) naming a window the files do not have, or
    one that holds no output sample of ``scene``, is a one-line error before any work."""
    from ..files.records import check_window
    for s in specs:
        said = flag or ("--until" if hasattr(s, "relative") else "--require")
        if s.window is not None and s.window not in WINDOWS:
            raise OptionError(f"{said} {s.text!r}: unknown window {s.window!r}; choose one of {', '.join(WINDOWS)}")
        if scene is not None:
            try:
                check_window(scene, s.window or "whole")
            except ValueError as exc:
                raise OptionError(f"{said} {s.text!r}: {str(exc).split(': ', 1)[1]}") from None


def robot_measures(specs: list, model: str, flag: str | None = None) -> None:
    """A --require, --spec or --event on a quantity the ``model`` level's numbers do not measure the robot in
    (the paper level's velocities and accelerations measure its step) is a one-line error: a verdict on it
    would pass or fail the step, not the design."""
    for s in specs:
        if step_measured(model, (s.quantity,)):
            raise OptionError(f"{flag or '--require'} {s.text!r}: the {model} level's {s.quantity} errors "
                              f"{STEP_WORDS}; judge them at the contact level (or elastic, without clearances)")


def judge(ds, specs: list, confidence: float = CONFIDENCE) -> list:
    """Verdicts of the specs on an ensemble (or single-run) Dataset; a window the file lacks is a
    one-line error."""
    from ..analysis.gate import judge_all
    try:
        return judge_all(specs, ds, confidence)
    except ValueError as exc:
        raise OptionError(str(exc)) from None


def verdict_attrs(verdicts: list) -> dict:
    """File attributes of the verdicts: the overall one and each as strict JSON (SI values)."""
    from ..analysis.gate import overall, verdicts_json
    return {"requirements_verdict": overall(verdicts),
            "requirements": json.dumps(verdicts_json(verdicts), allow_nan=False)}


def annotator(specs: list, verdicts: list):
    """The hook that judges the finished ensemble and puts the verdicts in its attributes; the
    verdicts are also appended to ``verdicts`` for the caller."""
    if not specs:
        return None

    def annotate(ds) -> dict:
        verdicts[:] = judge(ds, specs)
        return verdict_attrs(verdicts)
    return annotate
