"""One status vocabulary and one failure message for every level (rigid to contact).

A run either finishes or fails; a failed run says what went wrong, when (time
and step) and with which step size, in the same words at every level:
"<what> at t = 0.0013 s, step 13, with a 0.0001 s step".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FINISHED", "FAILED", "STATUSES", "DIVERGENCE_LIMIT", "NEWTON_FAILED", "DIVERGED",
           "failure_message", "diverged", "Outcome", "check_history", "contact_failure"]

FINISHED = "finished"
FAILED = "failed"
STATUSES = (FINISHED, FAILED)

DIVERGENCE_LIMIT = 1.0   # m or rad: a platform or link displacement this large is a failure, not a result

# failure codes the contact kernel writes (it reads these at compile time: renumbering them
# needs a fresh numba cache); their wording is the table in :func:`contact_failure`
NEWTON_FAILED = 1
DIVERGED = 2


def failure_message(what: str, t: float, step: int, h: float) -> str:
    """``what`` went wrong at time t (s) in step ``step`` (1 = the first) of length h (s)."""
    return f"{what} at t = {t:.6g} s, step {int(step)}, with a {h:.3g} s step"


def diverged(quantity: str, size: float, limit: float) -> str:
    """The ``what`` of a divergence: ``quantity`` reached ``size`` (m or rad) beyond ``limit``."""
    return f"{quantity} {size:.3g} exceeds the {limit:g} m divergence limit or is not finite"


@dataclass(frozen=True)
class Outcome:
    """How a run ended: its status (one of STATUSES), the failure message ('' when finished) and the
    steps it completed soundly."""
    status: str
    message: str
    steps: int


def check_history(d: np.ndarray, t: np.ndarray, quantity: str, limit: float = DIVERGENCE_LIMIT) -> Outcome:
    """The :class:`Outcome` of a history d (T, ...) on the grid t: failed at the first sample that is not
    finite or reaches ``limit``; its steps count the sound steps before it."""
    magnitude = np.abs(d)
    if magnitude.max(initial=0.0) < limit:           # the usual case in one contiguous pass (NaN fails it)
        return Outcome(FINISHED, "", len(t) - 1)
    size = magnitude.reshape(len(t), -1).max(-1)
    bad = ~(size < limit)                            # nan compares false: bad
    if not bad.any():
        return Outcome(FINISHED, "", len(t) - 1)
    k = int(np.argmax(bad))
    h = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return Outcome(FAILED, failure_message(diverged(quantity, size[k], limit), t[k], k, h), max(k - 1, 0))


def contact_failure(code: int, t: float, step: int, h: float, size: float, limit: float,
                    iterations: int) -> str:
    """The message of a contact-kernel failure ``code`` (the one table from codes to words)."""
    what = {NEWTON_FAILED: f"Newton on the contact forces did not converge in {iterations} iterations",
            DIVERGED: diverged("displacement", size, limit)}[int(code)]
    return failure_message(what, t, step, h)
