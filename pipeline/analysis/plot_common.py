"""What every rss6 figure shares: the Agg backend, units per direction family, titles, legends, saving.

The Agg backend is set once, here; also plain ticks, the 2 x 3 panel grid and the steady window's mark."""
from __future__ import annotations

import os
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rss6core import FAILED  # noqa: E402

from ..vocabulary import DIRECTIONS, FINISHED, UserError  # noqa: E402
from ..vocabulary import FAMILIES as _FAMILIES  # noqa: E402

__all__ = ["plt", "SI_UNITS", "FAMILY_DIRECTIONS", "figure_unit", "family_units", "si_text", "figure_title",
           "realisation_count", "plain_ticks", "panel_grid", "save_figure", "save_figures", "mark_steady",
           "legend_entries", "figure_legend"]

SI_UNITS = {"displacement": ("m", "rad"), "velocity": ("m/s", "rad/s"),   # translation, rotation
            "acceleration": ("m/s$^2$", "rad/s$^2$")}
FAMILY_DIRECTIONS = tuple(_FAMILIES.values())   # translations, rotations: one unit each per figure


def figure_unit(quantity: str, direction: str, values=None) -> tuple[float, str]:
    """Display factor from SI and unit of a figure axis, suited to the magnitude of ``values``
    (SI): the SI unit (m, m/s, m/s^2; rad, rad/s, rad/s^2) when they reach 1, else its milli-
    unit (mm, mm/s, mm/s^2; mrad, ...).  Without values: the milli-unit."""
    unit = SI_UNITS[quantity][direction not in ("x", "y", "z")]
    peak = np.nanmax(np.abs(values)) if values is not None and np.size(values) else np.nan
    if np.isfinite(peak) and peak >= 1.0:
        return 1.0, unit
    return 1e3, "m" + unit


def _direction_peaks(*values) -> np.ndarray:
    """(direction,) the largest finite |value| per direction over arrays (..., direction), SI;
    NaN where none is finite."""
    peaks = np.full(len(DIRECTIONS), -np.inf)
    for v in values:
        a = np.abs(np.asarray(v, float)).reshape(-1, len(DIRECTIONS))
        peaks = np.maximum(peaks, np.max(np.where(np.isfinite(a), a, -np.inf), axis=0, initial=-np.inf))
    return np.where(np.isfinite(peaks), peaks, np.nan)


def family_units(quantity: str, *values) -> dict[str, tuple[float, str]]:
    """{direction: (factor from SI, unit)} of one figure: one :func:`figure_unit` per direction
    family (FAMILY_DIRECTIONS), chosen by the family's largest |value| over every array of ``values``
    ((..., direction) SI), so that no two panels of a family show one quantity in two units."""
    peaks, units = _direction_peaks(*values), {}
    for family in FAMILY_DIRECTIONS:
        p = peaks[[DIRECTIONS.index(d) for d in family]]
        units |= dict.fromkeys(family, figure_unit(quantity, family[0], p[np.isfinite(p)]))
    return units


def si_text(value: float, unit: str) -> str:
    """``value`` (SI, in ``unit``) with the SI prefix that puts it in [1, 1000), 3 digits: '20 nm'."""
    prefixes = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"))
    scale, prefix = next((p for p in prefixes if abs(value) >= p[0]), prefixes[0 if value == 0 else -1])
    return f"{value / scale:.3g} {prefix}{unit}"


def realisation_count(ds, n: int) -> str:
    """'n = 41 finished of 100 (59 failed)': the ``n`` realisations a figure of ``ds`` draws, and, where
    any of the file's realisations failed, of how many and how many failed; 'n = 100' where none did.
    Every figure's n comes from here, so that no figure hides its failed realisations."""
    status = ds["status"].values.astype(str) if "status" in ds else np.array([FINISHED] * n)
    finished, total = int((status == FINISHED).sum()), status.size
    failed = int((status == FAILED).sum())
    if not failed:
        return f"n = {n}"
    return (f"n = {n} finished of {total} ({failed} failed)" if n == finished
            else f"n = {n}; {failed} of the file's {total} realisations failed")


def figure_title(what: str, ds, n: int | None = None, width: int = 110) -> str:
    """A title naming what is drawn, the scene, the level, n (and the failed realisations) and the file,
    wrapped to ``width``."""
    a = ds.attrs
    source = Path(str(ds.encoding.get("source", "in-memory data"))).name
    count = "" if n is None else f", {realisation_count(ds, n)}"
    head = f"{what}: scene {a.get('scene_name', '?')}, {a.get('model', '?')} level{count}, {source}"
    return "\n".join(textwrap.wrap(head, width))


def plain_ticks(ax) -> None:
    """Tick labels as plain numbers: no offset text or exponent to collide with titles."""
    for axis in ("x", "y"):
        if getattr(ax, f"get_{axis}scale")() == "linear":
            ax.ticklabel_format(axis=axis, style="plain", useOffset=False)


def panel_grid(title: str):
    """A figure of 2 x 3 panels, one per direction, under ``title``; its axes flattened."""
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    fig.suptitle(title)
    return fig, axes.ravel()


def save_figure(fig, path: Path) -> Path:
    """Write ``fig`` as a PNG to ``path`` (through a temporary file, renamed when whole) and close it; a write
    that fails (a full disk) is one line naming the file, and neither it nor Ctrl-C leaves a partial file,
    which a rerun would take for a figure already drawn."""
    part = Path(f"{path}.part")
    try:
        fig.savefig(part, dpi=110, format="png")
        os.replace(part, path)
    except OSError as exc:
        raise UserError(f"{path}: the figure could not be written: {exc.strerror or exc}") from None
    finally:
        part.unlink(missing_ok=True)
        plt.close(fig)
    return path


def mark_steady(ax, ds) -> None:
    """A dotted vertical line at the start of the steady window (the file's steady_after_s, s)."""
    if "steady_after_s" in ds.attrs:
        t_s = float(ds.attrs["steady_after_s"])
        ax.axvline(t_s, color="0.4", ls=":", lw=1.0, label=f"steady from {t_s:g} s")


def legend_entries(axes) -> dict:
    """Every distinct label of ``axes`` with its first handle, so that a mark drawn in any panel is
    explained even when the first panel lacks it."""
    handles = {}
    for ax in axes:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    return handles


def figure_legend(fig, axes) -> None:
    """One legend under the panels with every distinct label of ``axes`` (:func:`legend_entries`)."""
    handles = legend_entries(axes)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", fontsize=8,
               ncols=min(3, len(handles)))


def save_figures(figs: dict, out_dir) -> list[Path]:
    """Write {file name: Figure} into the folder ``out_dir`` (made if missing); the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out / name) for name, fig in figs.items()]
