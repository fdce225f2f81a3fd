"""What fails: the failure domain of a reliability run, in the standard normal space of its inputs.

Each input z_i is N(0, 1) by its law. Among the failing evaluations of the last level (subset
simulation: the states conditional on the failure event, candidates that left it excluded; plain
Monte Carlo: every draw), its mean is the shift that failing imposes and its std the narrowing: for
a linear limit state alpha . z > beta (|alpha| = 1), z given failure has mean alpha phi(beta) /
Phi(-beta), along the design point beta alpha, and std 1 across it. Grouped by the family an input
belongs to (a clearance block such as C_magnitude over the six legs, or one [uncertain.*] input),
the root mean square of its inputs' mean shifts ranks what drives the failures (per input, so that
families of different sizes compare; the family 'unused', inputs no draw uses, shows the noise).
The most probable failing realisation is the failing evaluation of smallest |z| (the largest
standard normal density), an estimate of the design point. Subset states are correlated along
their chains, so the means carry more noise than n independent draws would.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FailureDomain", "failure_domain", "format_failure_domain", "failure_domain_json"]


@dataclass(frozen=True)
class FailureDomain:
    """Per input (labels, groups): mean and std of z over the ``failing`` evaluations of ``level``;
    the most probable failing evaluation (index into the file's evaluations) and its z."""

    labels: tuple[str, ...]
    groups: tuple[str, ...]
    mean: np.ndarray
    std: np.ndarray
    level: int
    failing: int
    most_probable: int
    most_probable_z: np.ndarray

    def group_shifts(self) -> list[tuple[str, float, int]]:
        """(group, root mean square of its inputs' mean shifts, inputs in it), the largest first."""
        names = list(dict.fromkeys(self.groups))
        members = np.array(self.groups)
        out = [(g, float(np.sqrt(np.mean(self.mean[members == g] ** 2))), int(np.sum(members == g)))
               for g in names]
        return sorted(out, key=lambda item: -item[1])


def failure_domain(z: np.ndarray, level: np.ndarray, failing: np.ndarray, labels, groups) -> FailureDomain:
    """The failure domain of evaluations z (E, d) at levels (E,) of which ``failing`` (E,) are in the
    event. The statistics are over the failing evaluations of the highest level that has any (at
    least two); the most probable over every failing evaluation. ValueError when none fails."""
    z, level, failing = np.asarray(z, float), np.asarray(level), np.asarray(failing, bool)
    if len(labels) != z.shape[1] or len(groups) != z.shape[1]:
        raise ValueError(f"{z.shape[1]} inputs, but {len(labels)} labels and {len(groups)} groups")
    if not failing.any():
        raise ValueError("no evaluation is in the event: there is no failure domain to describe")
    levels = [k for k in np.unique(level[failing])[::-1] if np.count_nonzero(failing & (level == k)) >= 2]
    top = int(levels[0]) if levels else int(level[failing].max())
    chosen = z[failing & (level == top)]
    norms = np.where(failing, np.linalg.norm(z, axis=1), np.inf)
    best = int(np.argmin(norms))
    std = chosen.std(axis=0, ddof=1) if len(chosen) > 1 else np.full(z.shape[1], np.nan)
    return FailureDomain(tuple(labels), tuple(groups), chosen.mean(axis=0), std, top, len(chosen), best,
                         z[best].copy())


UNUSED = "unused"   # the family of inputs no draw uses (pipeline.studies.reliability.input_labels)


def _noise_note(group_shifts: list) -> list[str]:
    """The noise of the families' shifts (:meth:`FailureDomain.group_shifts`): that of the inputs no draw uses,
    which only chance moves. When no family stands above it the ranking says nothing; else families near it
    are not resolved at this sample."""
    shifts = {g: s for g, s, _ in group_shifts}
    noise = shifts.pop(UNUSED, None)
    if noise is None or not shifts:
        return []
    if max(shifts.values()) <= noise:
        return [f"  no family's shift exceeds the unused inputs' ({noise:.2f}, the noise of these means): "
                "the ranking is noise at this sample"]
    return [f"  noise: the unused inputs' shift is {noise:.2f} (only chance moves them; subset chains are "
            "correlated): a family not well above it is not resolved at this sample"]


def format_failure_domain(fd: FailureDomain, physical: list | None = None, shown: int = 8) -> str:
    """Lines: the groups by shift, the inputs of largest |mean|, the most probable failing realisation
    (its |z| and, where given, ``physical`` rows (name, values, unit) of its inputs)."""
    groups = fd.group_shifts()
    lines = [f"what fails: the standard-normal inputs z (z = Phi^-1 of each input's uniform, not the z direction) "
             f"of the {fd.failing} failing evaluations of level {fd.level} against N(0, 1) "
             "(mean = shift in standard deviations, std < 1 = narrowed)",
             "  families by the rms of their inputs' mean shifts: " + ", ".join(
                 [f"{g} {s:.2f}" + (f" ({n})" if n > 1 else "") for g, s, n in groups if g != UNUSED][:shown])]
    lines += _noise_note(groups)
    used = np.array([g != UNUSED for g in fd.groups])   # an input no draw uses cannot drive a failure
    order = [i for i in np.argsort(-np.abs(fd.mean)) if used[i]][:shown]
    lines.append("  inputs of largest shift: " + ", ".join(
        f"{fd.labels[i]} mean {fd.mean[i]:+.2f} std {fd.std[i]:.2f}" for i in order))
    near = [i for i in np.argsort(-np.abs(fd.most_probable_z)) if used[i]][:shown]
    lines.append(f"  most probable failing realisation: evaluation {fd.most_probable}, |z| = "
                 f"{np.linalg.norm(fd.most_probable_z):.3f}; largest |z_i|: " + ", ".join(
                     f"{fd.labels[i]} {fd.most_probable_z[i]:+.2f}" for i in near))
    lines += [f"    {name}: {' '.join(f'{v:.4g}' for v in values)} {unit}" for name, values, unit in physical or []]
    return "\n".join(lines)


def failure_domain_json(fd: FailureDomain, physical: list | None = None) -> dict:
    """The failure domain as strict JSON (None for a NaN std)."""
    from .stats import json_number
    return {"level": fd.level, "failing": fd.failing,
            "families": [{"family": g, "shift": s, "inputs": n} for g, s, n in fd.group_shifts()],
            "inputs": [{"input": label, "family": g, "mean": json_number(m), "std": json_number(s)}
                       for label, g, m, s in zip(fd.labels, fd.groups, fd.mean, fd.std)],
            "most_probable": {"evaluation": fd.most_probable, "norm": float(np.linalg.norm(fd.most_probable_z)),
                              "z": {label: float(v) for label, v in zip(fd.labels, fd.most_probable_z)},
                              "inputs": [{"input": name, "values": list(values), "units": unit}
                                         for name, values, unit in (physical or [])]}}
