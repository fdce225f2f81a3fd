"""Issue 43's burst near t = 1 s: which joint's stick-slip starts it, and at what frequency it rings.

The case of benchmarks/acceleration_candidates.py (configs/paper.toml, settle_time_s = 0.3, contact
level, realisation 0 of seed 0) on the numpy stepper with no switch (the compiled kernel's digits),
recording at every accepted step each spherical joint's normal force and sliding speed (eq. 18's
argument: the tangential part of de + R omega x n, omega the ideal relative rotation). It prints:

- the steady window's largest |acceleration error| per direction and its time;
- per joint family, the legs whose sliding speed is inside eq. 18's ramp [v0, v1] (neither stuck
  nor fully sliding) in the 100 ms (LOOK_BACK) before the ry peak, and the times they entered it;
- the joints losing or regaining contact, and the spherical joints whose sliding direction turns
  fastest, in the same 100 ms;
- the dominant frequencies of the ry and z acceleration error over 0.9-1.1 s (FFT of the 1 ms
  output, the 10 ms running mean removed, as docs/accelerations.md's burst amplitude) against the
  lowest natural frequencies of the elastic robot at t = 1 s with the joints rigid.

    python benchmarks/acceleration_burst.py [--realization K]
"""
import argparse
import dataclasses

import numpy as np

from acceleration_candidates import SCENE, SETTLE, Switched
from rss6core.assembly import build_elastic_model, dense_matrices, system_at
from rss6core.clearance import draw_clearances
from rss6core.contact_dynamics import _joint_nodes, _relative, simulate_contact
from rss6core.kinematics import rigid_motion
from rss6core.models import prepare_level
from rss6core.scene import load_scene

DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
LOOK_BACK = 0.1    # s before the ry peak in which a joint's entry into the ramp is reported


class Recording(Switched):
    """The plain numpy stepper (no switch) that records each accepted step's time s, spherical-joint
    normal forces (6, 2) N, sliding speeds (6, 2) m/s and sliding velocities (6, 2, 3) m/s, joints C
    and B, and the revolutes' contact force magnitudes (6,) N, in the class's ``log``."""
    log: list = []

    def _keep(self, kept, ch, k1, h, a, d, v, f, delta, rate, used):
        super()._keep(kept, ch, k1, h, a, d, v, f, delta, rate, used)
        jm = self.setup.jm
        e = _relative(ch, k1, *_joint_nodes(jm, d[0]))[:, 1:]
        de = _relative(ch, k1, *_joint_nodes(jm, v[0]))[:, 1:]
        normal = e / np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-300)
        radius = float(np.asarray(ch.radius).reshape(-1)[1])
        slip = de + radius * np.cross(ch.omega[k1][:, 1:], normal)
        slip -= (slip * normal).sum(-1, keepdims=True) * normal
        force = np.maximum(-(f[0][:, 1:] * normal).sum(-1), 0.0)
        type(self).log.append((float(ch.t[k1]), force, np.linalg.norm(slip, axis=-1),
                               np.linalg.norm(f[0][:, 0], axis=-1), slip))


def _steady_peaks(b) -> list[tuple[str, float, float]]:
    """(direction, max |acceleration error|, its time s) over t >= SETTLE."""
    inside = np.flatnonzero(b.t >= SETTLE - 1e-12)
    acc = np.abs(b.acceleration[0, inside])
    return [(name, float(acc[:, k].max()), float(b.t[inside[acc[:, k].argmax()]])) for k, name in enumerate(DIRECTIONS)]


def _ramp_entries(log, contact, t_peak: float) -> list[str]:
    """The joints inside eq. 18's ramp in the LOOK_BACK before ``t_peak``, with when they entered it."""
    t = np.array([row[0] for row in log])
    force = np.stack([row[1] for row in log])
    speed = np.stack([row[2] for row in log])
    ramp = (force > 0) & (speed >= contact.stick_velocity) & (speed <= contact.slip_velocity)
    window = (t >= t_peak - LOOK_BACK) & (t <= t_peak)
    lines = []
    found = sorted((t[window][np.argmax(ramp[window][:, leg, joint])], leg, joint)
                   for leg, joint in zip(*np.nonzero(ramp[window].any(0))))
    for entered, leg, joint in found:
        lines.append(f"  {'CB'[joint]}{leg + 1}: in the ramp from t = {entered:.4f} s "
                     f"({(t_peak - entered) * 1e3:.1f} ms before), force {force[window][:, leg, joint].max():.3g} N, "
                     f"slowest sliding {speed[window][:, leg, joint].min():.3g} m/s")
    return lines or ["  none"]


def _separations(log, t_peak: float) -> list[str]:
    """The joints that lose or regain contact (force 0 <-> positive) in the LOOK_BACK before ``t_peak``."""
    t = np.array([row[0] for row in log])
    touching = np.concatenate([np.stack([row[3] for row in log])[..., None], np.stack([row[1] for row in log])],
                              -1) > 0                                         # (steps, 6, 3) A, C, B
    window = np.flatnonzero((t >= t_peak - LOOK_BACK) & (t <= t_peak))
    change = touching[window[1:]] != touching[window[:-1]]
    lines = []
    for step, leg, joint in zip(*np.nonzero(change)):
        what = "regains" if touching[window[step + 1], leg, joint] else "loses"
        lines.append(f"  {'ACB'[joint]}{leg + 1} {what} contact at t = {t[window[step + 1]]:.4f} s")
    return lines or ["  none: every joint stays in contact"]


def _fastest_turns(log, t_peak: float, count: int = 4) -> list[str]:
    """The spherical joints whose sliding direction (hence their friction force's) turns fastest in
    the LOOK_BACK before ``t_peak``: the largest angle per accepted step over its step (rad/s)."""
    t = np.array([row[0] for row in log])
    slip = np.stack([row[4] for row in log])                              # (steps, 6, 2, 3)
    unit = slip / np.maximum(np.linalg.norm(slip, axis=-1, keepdims=True), 1e-300)
    window = np.flatnonzero((t >= t_peak - LOOK_BACK) & (t <= t_peak))
    cosine = np.clip((unit[window[1:]] * unit[window[:-1]]).sum(-1), -1.0, 1.0)
    rate = np.arccos(cosine) / np.diff(t[window])[:, None, None]          # (steps, 6, 2) rad/s
    best = rate.max(0)
    order = np.argsort(best, axis=None)[::-1][:count]
    lines = []
    for leg, joint in zip(*np.unravel_index(order, best.shape)):
        at = t[window[1:]][rate[:, leg, joint].argmax()]
        lines.append(f"  {'CB'[joint]}{leg + 1}: {best[leg, joint]:.3g} rad/s at t = {at:.4f} s "
                     f"({(t_peak - at) * 1e3:.1f} ms before)")
    return lines


def _spectrum_peaks(b, k: int, count: int = 3) -> list[float]:
    """The ``count`` strongest frequencies (Hz) of direction k's acceleration error over 0.9-1.1 s,
    its 10 ms running mean removed."""
    inside = (b.t >= 0.9) & (b.t <= 1.1)
    x = b.acceleration[0, inside, k]
    dt = float(b.t[1] - b.t[0])
    width = max(1, int(round(0.01 / dt)))
    x = x - np.convolve(x, np.ones(width) / width, mode="same")
    power = np.abs(np.fft.rfft(x * np.hanning(len(x)))) ** 2
    freq = np.fft.rfftfreq(len(x), dt)
    return [float(f) for f in freq[np.argsort(power[1:])[::-1][:count] + 1]]


def _robot_frequencies(scene, elements: int, t: float, count: int = 8) -> np.ndarray:
    """The elastic robot's lowest natural frequencies (Hz) at time t, joints rigid (eq. 32's M, K)."""
    model = build_elastic_model(scene, elements)
    maps, _ = system_at(model, rigid_motion(scene, np.array([t])), scene)
    M, K = dense_matrices(model, maps[0])
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)
    return np.sqrt(np.clip(w2[:count], 0.0, None)) / (2 * np.pi)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--realization", type=int, default=0)
    args = p.parse_args(argv)
    base = load_scene(SCENE)
    scene = dataclasses.replace(base, simulation=dataclasses.replace(base.simulation, settle_time=SETTLE))
    level = prepare_level(scene, "contact")
    stepper = type("recording", (Recording,), {"log": []})
    b = simulate_contact(scene, [draw_clearances(scene, 0, args.realization)], level.elements, level.integrator,
                         level.dt, stepper=stepper)
    peaks = _steady_peaks(b)
    for name, value, at in peaks:
        print(f"{name:>2} max |acceleration error| {value:.4g} at t = {at:.4f} s")
    t_ry = dict((n, at) for n, _, at in peaks)["ry"]
    print(f"spherical joints inside eq. 18's ramp [{scene.contact.stick_velocity:g}, "
          f"{scene.contact.slip_velocity:g}] m/s in the {LOOK_BACK * 1e3:.0f} ms before the ry peak:")
    print("\n".join(_ramp_entries(stepper.log, scene.contact, t_ry)))
    print(f"joints losing or regaining contact in the {LOOK_BACK * 1e3:.0f} ms before the ry peak:")
    print("\n".join(_separations(stepper.log, t_ry)))
    print(f"spherical joints whose sliding direction turns fastest in the {LOOK_BACK * 1e3:.0f} ms before the ry peak:")
    print("\n".join(_fastest_turns(stepper.log, t_ry)))
    for k in (2, 4):
        print(f"{DIRECTIONS[k]} acceleration error, 0.9-1.1 s, strongest frequencies: "
              + ", ".join(f"{f:.0f} Hz" for f in _spectrum_peaks(b, k)))
    print("elastic robot at t = 1 s, joints rigid, lowest frequencies: "
          + ", ".join(f"{f:.0f}" for f in _robot_frequencies(scene, level.elements, 1.0)) + " Hz")


if __name__ == "__main__":
    main()
