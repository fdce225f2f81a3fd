"""Heat maps of a workspace error map (``rss6 map``): per direction the worst case and the q95 over the
grid, unreachable poses masked (grey), the trajectory's path drawn, units on axes and colour bars."""
from __future__ import annotations

import textwrap

import numpy as np

from ..vocabulary import DIRECTIONS, QUANTILES, family_of
from .plot_common import figure_unit, plt

__all__ = ["map_figures", "direction_map_figure", "q95_caveat", "axis_display"]

_PANELS = (("worst_case", "worst case over every clearance state"), ("q95", "q95 over the drawn realisations"))


def axis_display(ds, dim: str) -> tuple[float, str]:
    """Display factor from SI and unit of a grid axis: mm for positions, deg for angles."""
    return (1e3, "mm") if ds[dim].attrs["units"] == "m" else (180.0 / np.pi, "deg")


def _fixed_pose(ds) -> str:
    """The pose axes the grid holds fixed, e.g. 'x = 0 mm, n1 = 0 deg'."""
    out = []
    for name, coord in ds.coords.items():
        if str(name).startswith("platform_") and coord.ndim == 0:
            factor, unit = axis_display(ds, name)
            out.append(f"{str(name).removeprefix('platform_')} = {round(float(coord) * factor, 3) + 0.0:g} {unit}")
    return ", ".join(out)


def q95_caveat(ds) -> str | None:
    """What a map's q95 is when its draws are too few for the q95's two-sided interval (None otherwise):
    a sample quantile of so few draws is a rough point estimate, not a bound."""
    from .estimators import min_n_for_quantile
    n, confidence = int(ds.attrs["n_draws"]), float(ds.attrs["confidence"])
    needed = min_n_for_quantile(QUANTILES["q95"], confidence)
    if n >= needed:
        return None
    return (f"q95 from {n} draws per pose: a point estimate without its {100 * confidence:g} % interval, "
            f"which needs n >= {needed} (-n)")


def _trajectory_on_grid(ax, px, py, x, y) -> None:
    """The trajectory's projected path, within the grid's cells (x, y their centres): where it leaves the
    grid the axes stay on the grid, and the legend says the path is cut there."""
    ax.plot(px, py, color="w", lw=1.6)
    extent = [_cell_edges(x), _cell_edges(y)]
    outside = (px.min() < extent[0][0] or px.max() > extent[0][1] or py.min() < extent[1][0]
               or py.max() > extent[1][1])
    ax.plot(px, py, color="k", lw=0.8, label="trajectory (projected on these two axes"
            + ("; cut at the grid's edge, which it leaves)" if outside else ")"))
    ax.set(xlim=extent[0], ylim=extent[1])


def _cell_edges(centres: np.ndarray) -> tuple[float, float]:
    """The outer edges of pcolormesh's 'nearest' cells around sorted ``centres`` (half a cell beyond each end;
    a grid axis has two or more points, --grid's N >= 2)."""
    return (float(centres[0] - (centres[1] - centres[0]) / 2),
            float(centres[-1] + (centres[-1] - centres[-2]) / 2))


def direction_map_figure(ds, direction: str):
    """The worst case and the q95 of |error| in ``direction`` over the grid, side by side."""
    from matplotlib.patches import Patch
    family = family_of(direction)
    rows, columns = ds["reachable"].dims
    (fa, ua), (fb, ub) = axis_display(ds, columns), axis_display(ds, rows)
    x, y = ds[columns].values * fa, ds[rows].values * fb
    worst = ds[f"worst_case_{family}"].sel({family: direction}).values
    scale, unit = figure_unit("displacement", direction, worst[np.isfinite(worst)])
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.8")
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    for ax, (field, what) in zip(axes, _PANELS):
        values = np.ma.masked_invalid(ds[f"{field}_{family}"].sel({family: direction}).values * scale)
        mesh = ax.pcolormesh(x, y, values, shading="nearest", cmap=cmap)
        fig.colorbar(mesh, ax=ax, label=f"|{direction} error| [{unit}]")
        _trajectory_on_grid(ax, ds[f"path_{columns}"].values * fa, ds[f"path_{rows}"].values * fb, x, y)
        caveat = q95_caveat(ds) if field == "q95" else None
        title = [what] + (textwrap.wrap(f"({caveat})".replace(" %", "\u00a0%"), 60) if caveat else [])
        ax.set(xlabel=f"{ds[columns].attrs['long_name']} [{ua}]", ylabel=f"{ds[rows].attrs['long_name']} [{ub}]",
               title="\n".join(title))
        ax.title.set_fontsize(10)
    handles = [axes[0].get_legend_handles_labels()[0][0]]
    if not ds["reachable"].values.all():
        handles.append(Patch(color="0.8", label="unreachable"))
    fig.legend(handles=handles, loc="outside lower center", fontsize=8, ncols=2)
    head = (f"{ds.attrs.get('model', '?')} level, |{direction} pose error| over the workspace: "
            f"scene {ds.attrs.get('scene_name', '?')}, "
            f"{ds.attrs.get('n_draws', '?')} draws (seed {ds.attrs.get('seed', '?')}), "
            f"worst case with {ds.attrs.get('clearance_sizes', '?')}")
    # wrapped: a banded scene's list of size bands ran past both edges of the figure
    fig.suptitle("\n".join(textwrap.wrap(head, 130)) + f"\nother pose axes fixed at the trajectory's mean: "
                 f"{_fixed_pose(ds)}", fontsize=10)
    return fig


def map_figures(ds) -> dict:
    """{file name: figure}: workspace_map_<direction>.png for each direction."""
    return {f"workspace_map_{d}.png": direction_map_figure(ds, d) for d in DIRECTIONS}
