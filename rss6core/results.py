"""What every level returns: one realisation's platform error histories, a contact batch, the time grid."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SimulationResult", "ContactBatch", "time_grid", "check_step_count", "whole_steps", "PEAK_WINDOWS"]

PEAK_WINDOWS = ("startup", "steady")   # axis 0 of the peaks: t < steady_after, t >= steady_after


@dataclass(frozen=True)
class SimulationResult:
    """Platform elastic error (actual minus ideal rigid pose) and solver diagnostics, SI."""
    t: np.ndarray             # (T,) s
    displacement: np.ndarray  # (T, 6) x, y, z [m], rx, ry, rz [rad]
    velocity: np.ndarray      # (T, 6) m/s, rad/s
    acceleration: np.ndarray  # (T, 6) m/s^2, rad/s^2
    status: str               # :data:`.status.FINISHED` or :data:`.status.FAILED`
    message: str              # why it failed (:func:`.status.failure_message`), else ""
    steps: int                # steps taken
    states: tuple | None = None  # full (d, v, a) histories (T, N) when asked for
    peak_abs_error: np.ndarray | None = None      # (2, 3, 6) max |error| over internal steps, if
                                                  # finer, per window of PEAK_WINDOWS
    contact_force_peak: np.ndarray | None = None  # (18,) N, joints A1..A6, C1..C6, B1..B6
    iterations: int = 0                           # Newton iterations (contact level)
    draw: object | None = None  # the ClearanceDraw an ensemble file records (clearance levels)
    inputs: object | None = None  # the uncertain.InputDraw of a scene with [uncertain.*] inputs


@dataclass
class ContactBatch:
    """Results of a batch of contact-level realisations (leading axis R), on the output time grid."""
    t: np.ndarray                 # (T,) s
    displacement: np.ndarray      # (R, T, 6)
    velocity: np.ndarray
    acceleration: np.ndarray
    peak: np.ndarray              # (R, 2, 3, 6) max |error| over every internal step per PEAK_WINDOWS
    contact_peak: np.ndarray      # (R, 18) max |contact force| per joint A1..A6, C1..C6, B1..B6, N
    status: list
    message: list
    steps: np.ndarray             # (R,) internal steps completed
    iterations: np.ndarray        # (R,) Newton iterations in all
    refined: np.ndarray           # (R,) attempts refused (each retried as two half steps)

    def result(self, k: int) -> SimulationResult:
        return SimulationResult(self.t, self.displacement[k], self.velocity[k], self.acceleration[k],
                                self.status[k], self.message[k], int(self.steps[k]),
                                peak_abs_error=self.peak[k], contact_force_peak=self.contact_peak[k],
                                iterations=int(self.iterations[k]))


MIN_STEPS, MAX_STEPS = 10, 1_000_000   # a run's output steps: enough for its windows, few enough for its memory


def check_step_count(duration: float, dt: float) -> int:
    """The number of output steps of a run of ``duration`` s at ``dt`` s, or ValueError where the step
    does not divide the duration or gives fewer than MIN_STEPS or more than MAX_STEPS steps (the run's
    histories and derivatives need a few samples; each step holds arrays for every realisation).
    Counted, not built: the grid it guards may not fit in memory."""
    steps = whole_steps(duration, dt)
    if not MIN_STEPS <= steps <= MAX_STEPS:
        count = f"{steps}" if steps < 1e15 else f"about {float(steps):.3g}"
        raise ValueError(f"time step {dt!r} s gives {count} steps over the duration {duration!r} s; a run takes "
                         f"{MIN_STEPS} to {MAX_STEPS} steps")
    return steps


def time_grid(duration: float, dt: float) -> np.ndarray:
    """t_k = k dt on [0, duration]; dt must divide the duration."""
    return np.arange(whole_steps(duration, dt) + 1) * dt


def whole_steps(duration: float, dt: float, at_least: int = 0) -> int:
    """How many steps of ``dt`` make ``duration`` (s), or ValueError where dt does not divide it into
    at least ``at_least`` of them."""
    if not dt > 0:
        raise ValueError(f"time step must be positive, got {dt!r}")
    n = duration / dt
    if abs(n - round(n)) > 1e-6 * max(1.0, n) or round(n) < at_least:
        raise ValueError(f"time step {dt!r} s does not divide the duration {duration!r} s")
    return int(round(n))
