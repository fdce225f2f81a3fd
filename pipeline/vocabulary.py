"""The words every part of the pipeline shares, each written once: quantities, directions and their
families, analysis windows, statistics and quantiles, summaries, stores, the default confidence,
and the kinds of user mistake that end a command with one line and exit code 2.

A leaf: it imports nothing of the pipeline, so every part may import it."""
from __future__ import annotations

from rss6core import FINISHED, MODELS, model_level

__all__ = ["QUANTITIES", "DIRECTIONS", "FAMILIES", "family_of", "WINDOWS", "window_words", "QUANTILES", "STATISTICS",
           "REQUIRABLE", "SUMMARIES", "STORES", "CONFIDENCE", "UNMEASURED_LEVEL", "at_measured_level", "FINISHED",
           "ESTIMATE_ENDS", "step_measured", "STEP_WORDS", "counted", "UserError", "OptionError"]

QUANTITIES = ("displacement", "velocity", "acceleration")   # of the platform's pose error
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")             # translations (m), rotations (rad)
FAMILIES = {"translation": DIRECTIONS[:3], "rotation": DIRECTIONS[3:]}   # one unit each


def family_of(direction: str) -> str:
    """The family of ``direction`` (a key of FAMILIES): 'translation' (m) or 'rotation' (rad)."""
    return next(f for f, members in FAMILIES.items() if direction in members)


WINDOWS = ("whole", "startup", "steady")   # analysis windows: [settle, T], [settle, t_s), [max(settle, t_s), T]


def window_words(window: str | None) -> str:
    """How a printed line names the part of the run a number is over: 'whole run' (also for None,
    a file without windows), else 'steady window', 'startup window'."""
    return "whole run" if window in (None, "whole") else f"{window} window"


QUANTILES = {"q05": 0.05, "q50": 0.5, "q95": 0.95, "q99": 0.99}   # name -> probability
STATISTICS = ("mean", "std", *QUANTILES, "max")   # the statistics of an ensemble, in table order
REQUIRABLE = tuple(s for s in STATISTICS if s != "max")   # those with an interval, for --require
SUMMARIES = ("max_abs_error", "mean_abs_error")   # per-realisation summaries over a window
STORES = ("summary", "full")   # --store: summaries only, or also the error histories
CONFIDENCE = 0.95   # the default confidence of every interval, bound and verdict
# the Sobol', multi-fidelity and subset-simulation intervals' coverage was measured at CONFIDENCE only
UNMEASURED_LEVEL = f"coverage measured at {100 * CONFIDENCE:g} % only"   # said at any other label


def at_measured_level(confidence: float) -> bool:
    """Whether ``confidence`` is the label (CONFIDENCE) at which the Sobol', multi-fidelity and subset intervals'
    coverage was measured (their benchmarks have no level option)."""
    return abs(confidence - CONFIDENCE) < 1e-12


STEP_WORDS = ("come from eccentricities redrawn every step and grow as the step shrinks: they measure the step, "
              "not the robot")   # said of such errors wherever a table, note or refusal meets them


def step_measured(model: str, quantities) -> list[str]:
    """Which of ``quantities`` the ``model`` level's errors measure its step in, not the robot: velocity and
    acceleration at a level that redraws its eccentricities every step (the paper level)."""
    if model not in MODELS or not model_level(model).redraws_every_step:
        return []
    return [q for q in ("velocity", "acceleration") if q in quantities]


# how a probability estimate (rss6 reliability: subset simulation or plain Monte Carlo) ended: its ``status``
ESTIMATE_ENDS = {
    "finished": "plain Monte Carlo ran the -n draws asked for; no convergence claimed",
    "converged": "subset simulation reached the limit, or the --cov target was met",
    "certain": "every level-0 draw exceeds the limit: P is 1 to within the sample",
    "impossible": "a constant response below the limit at every level-0 draw: P is 0 to within the sample",
    "stalled": "subset's threshold stopped rising (a flat or discontinuous response): no estimate",
    "max_levels": "subset's last level ended below the limit: no estimate",
    "budget": "--budget ended the runs before the --cov target was met",
}


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless n is 1: '1 finished realisation', '4 class combinations'."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


class UserError(ValueError):
    """A mistake of the user's (an option, a file, a spec): one line, exit code 2, no traceback."""


class OptionError(UserError):
    """An option value or a combination of options that cannot work; the message names the option."""
