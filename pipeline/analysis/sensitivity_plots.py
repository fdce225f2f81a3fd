"""A sensitivity file's figures (``rss6 sensitivity``): bar charts of first-order and total Sobol' indices."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..vocabulary import DIRECTIONS, QUANTITIES
from .plot_common import figure_title, panel_grid, save_figures

__all__ = ["sensitivity_figures", "plot_sensitivity"]

_DESIGN_NAMES = {"families": "joint family", "joints": "joint"}
_GROUP_LABELS = {"revolute_radial": "A radial", "revolute_axial": "A axial", "spherical_C": "C",
                 "spherical_B": "B"}


def _sobol_panel(ax, da, groups: list[str], direction: str) -> None:
    """S1 and ST bars per group with their interval as error bars, on one direction's axis."""
    x = np.arange(len(groups))
    for k, (index, shift) in enumerate((("S1", -0.2), ("ST", 0.2))):
        cell = da.sel(index=index, direction=direction)
        est = cell.sel(bound="estimate").values
        err = np.maximum(np.stack([est - cell.sel(bound="lower").values,   # bounds clipped to [0, 1], estimates
                                   cell.sel(bound="upper").values - est]), 0)   # not: one may lie outside its interval
        ax.bar(x + shift, est, width=0.4, yerr=err, capsize=2, color=f"C{k}", label=index,
               error_kw={"lw": 0.8})
    ax.set_xticks(x, [_GROUP_LABELS.get(g, g) for g in groups], fontsize=8,
                  rotation=90 if len(groups) > 6 else 0)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set(ylabel="Sobol' index [1]", title=direction)
    ax.grid(alpha=0.3, axis="y")


def sensitivity_figures(ds, quantities=QUANTITIES) -> dict:
    """{file name: Figure}: per statistic, quantity and grouping, a bar chart per direction of the
    first-order (S1) and total (ST) Sobol' indices with their bootstrap intervals."""
    figs = {}
    conf = f"{100 * float(ds.attrs['confidence']):g} %"
    for stat, what in (("max_abs_error", "max"), ("mean_abs_error", "mean")):
        for design in dict.fromkeys(str(v) for v in ds["group_design"].values):
            groups = [str(g) for g, d in zip(ds["group"].values, ds["group_design"].values) if d == design]
            for q in quantities:
                da = ds[f"{stat}_sobol"].sel(quantity=q, group=groups)
                window = da.attrs.get("analysis_window", "whole run")
                fig, axes = panel_grid(figure_title(
                    f"Sobol' indices of per-realisation {what} |{q} error|, {window}, by "
                    f"{_DESIGN_NAMES.get(design, design)}, bars: {conf} bootstrap intervals", ds,
                    int(ds.attrs["n_base_samples"])))
                for ax, d in zip(axes, DIRECTIONS):
                    _sobol_panel(ax, da, groups, d)
                axes[0].legend(fontsize=8, loc="upper right")
                figs[f"sobol_{what}_{q}_{design}.png"] = fig
    return figs


def plot_sensitivity(ds, out_dir) -> list[Path]:
    """Write a sensitivity file's bar charts to ``out_dir``."""
    return save_figures(sensitivity_figures(ds), out_dir)
