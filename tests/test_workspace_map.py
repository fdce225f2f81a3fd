"""The workspace error map (rss6core/workspace_map.py, ``rss6 map``): the closed-form worst case (docs/model.md
section 3, eq. M1-M3) bounds every realisation the quasi-static level computes, equals a brute-force
maximisation over the clearance sets, and the map marks unreachable poses instead of failing."""
import importlib.util
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.files.reading import load_netcdf
from rss6core import (ClearanceDraw, ball_support, draw_clearances, drawn_eccentricities, revolute_support,
                      rigid_motion, sampled_errors, static_closure, worst_case_error, worst_case_sizes)
from rss6core.quasi_static import quasi_static_error

THREE_TIMES = np.array([0.05, 0.3, 0.6])   # s: three different poses of the paper trajectory
DRAWS = 2000


def _closure_at(scene, t):
    motion = rigid_motion(scene, t)
    return motion, static_closure(scene.geometry, motion.platform.pose)


@pytest.mark.parametrize("name", ["paper", "paper_tolerance"])
def test_the_worst_case_bounds_every_quasi_static_realisation_at_three_poses(name, configs):
    """2000 realisations through the quasi-static level itself (quasi_static_error) at three poses:
    none exceeds the worst case (with a tolerance band: at its upper end), the largest comes within a
    sizeable fraction of it, and the map's vectorised errors are the level's."""
    from rss6core import load_scene
    scene = load_scene(configs / f"{name}.toml")
    motion, closure = _closure_at(scene, THREE_TIMES)
    worst = worst_case_error(closure, scene.geometry.w, worst_case_sizes(scene))
    level = np.abs(np.stack([quasi_static_error(scene, motion, draw_clearances(scene, 7, r))[0]
                             for r in range(DRAWS)], axis=1))          # (pose, draw, direction)
    assert np.all(np.isfinite(worst)) and closure.reachable.all()
    assert np.all(level.max(axis=1) <= worst * (1 + 1e-12))
    ratio = level.max(axis=1) / worst
    print(f"{name}: largest of {DRAWS} draws / worst case, three poses, six directions: "
          f"{ratio.min():.2f} .. {ratio.max():.2f}")   # pytest -s: docs/model.md section 3, docs/guide.md
    # measured 0.26 .. 0.38 (paper), 0.19 .. 0.29 (paper_tolerance, whose worst case takes every size at
    # its band's upper end): the worst case needs all 18 joints at once at their most harmful wall
    assert np.all(ratio >= 0.15)
    np.testing.assert_allclose(sampled_errors(closure, drawn_eccentricities(scene, DRAWS, 7)), level,
                               rtol=1e-9, atol=1e-15)


def _fibonacci_sphere(count: int) -> np.ndarray:
    k = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / count), np.pi * (1 + 5 ** 0.5) * k
    return np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], -1)


def _brute_force_state(scene, n: np.ndarray, g_row: np.ndarray, sizes) -> ClearanceDraw:
    """The clearance state maximising d_k = sum_i g_ki n_i . (e_A + e_C - e_B), each joint's eccentricity
    picked among a fine discretisation of its set's boundary (the revolute's rims as clearance.py spans
    them: radial in the plane of [cos u, sin u, 0] and Z, axial along w; the balls' surfaces)."""
    u, w = scene.geometry.base_angles, scene.geometry.w
    theta = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    sphere = _fibonacci_sphere(20000)
    e_A, e_C, e_B = np.empty((6, 3)), np.empty((6, 3)), np.empty((6, 3))
    for i in range(6):
        c = g_row[i] * n[i]
        radial = np.outer(np.cos(theta), [np.cos(u[i]), np.sin(u[i]), 0]) + np.outer(np.sin(theta), [0, 0, 1])
        rims = np.concatenate([sizes.revolute_radial * radial + s * sizes.revolute_axial * w[i] for s in (-1, 1)])
        e_A[i] = rims[np.argmax(rims @ c)]
        e_C[i] = sizes.spherical_C * sphere[np.argmax(sphere @ c)]
        e_B[i] = sizes.spherical_B * sphere[np.argmax(-(sphere @ c))]
    full = np.full(6, np.nan)
    return ClearanceDraw(full, full, full, full, e_A, e_C, e_B)


def test_the_worst_case_equals_a_brute_force_maximisation_within_1_percent(paper):
    """At one pose and in every direction: the maximising clearance state found joint by joint on
    discretised set boundaries, run through the quasi-static level, gives the closed form within 1 %."""
    motion, closure = _closure_at(paper, np.array([0.3, 0.31, 0.32]))
    sizes = worst_case_sizes(paper)
    worst = worst_case_error(closure, paper.geometry.w, sizes)[0]
    for k in range(6):
        state = _brute_force_state(paper, closure.n[0], closure.inverse[0, k], sizes)
        reached = quasi_static_error(paper, motion, state)[0][0, k]
        assert reached == pytest.approx(worst[k], rel=1e-2), k
        assert reached <= worst[k] * (1 + 1e-12)


def test_the_support_functions_in_closed_form_and_against_the_drawn_eccentricities(paper):
    """A revolute about Z: h(n) = radial |n_perp| + axial |n_z| (3-4-5 direction, along and across
    the axis, scaled); a ball: size |n|.  And every drawn e_A of clearance.py lies inside the set
    whose support function this is, reaching close to its boundary."""
    z, radial, axial = np.array([0.0, 0.0, 1.0]), 2e-4, 1e-4
    n = np.array([[0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.2, 0.0, 1.6]])
    np.testing.assert_allclose(revolute_support(n, z, radial, axial),
                               [0.6 * radial + 0.8 * axial, axial, radial, 2 * (0.6 * radial + 0.8 * axial)])
    np.testing.assert_allclose(ball_support(n, 3e-4), [3e-4, 3e-4, 3e-4, 6e-4])
    e_A = np.stack([draw_clearances(paper, 3, r).e_A for r in range(2000)])   # (draw, leg, 3)
    directions = _fibonacci_sphere(200)
    sizes = worst_case_sizes(paper)
    h = revolute_support(directions[:, None], paper.geometry.w[None], sizes.revolute_radial, sizes.revolute_axial)
    reach = np.einsum("dli,ki->dkl", e_A, directions).max(axis=0)          # (direction, leg)
    assert np.all(reach <= h * (1 + 1e-12))
    # 0.71 .. 0.997 measured: the rims' corners (radial and axial both at their size) are rarely drawn
    assert np.all(reach >= 0.65 * h) and (reach / h).max() >= 0.99


def _sibling(name: str):
    """A test module beside this one (the tests run in importlib mode: not importable by name)."""
    spec = importlib.util.spec_from_file_location(f"_{name}", Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _cf_errors():
    return _sibling("test_cf").cf_errors


def _unreachable_map(folder) -> Path:
    """``rss6 map`` on a grid reaching below the legs' reach (z down to -0.9 m); its output folder."""
    out = folder / "map"
    assert main(["map", "smoke", "--grid", "y:-0.05:0.05:5", "--grid", "z:-0.9:-0.35:6", "-n", "100",
                 "--seed", "3", "-o", str(out)]) == 0
    return out


def test_unreachable_poses_are_masked_not_an_error(tmp_path, capsys):
    """Poses out of reach are NaN and flagged unreachable; the command still writes its file and six
    heat maps."""
    out = _unreachable_map(tmp_path)
    ds = load_netcdf(out / "workspace_map.nc")
    reachable = ds["reachable"].values.astype(bool)
    assert 0 < reachable.sum() < reachable.size
    assert not reachable[ds["platform_z"].values < -0.8].any()
    for name in ("worst_case_translation", "q95_rotation", "q95_upper_rotation", "max_sampled_translation"):
        values = ds[name].values
        assert np.isnan(values[:, ~reachable]).all() and np.isfinite(values[:, reachable]).all(), name
    for family in ("translation", "rotation"):   # 100 draws: the q95's 95 % interval exists (n >= 59)
        lower, q95, upper = (ds[f"{k}_{family}"].values[:, reachable] for k in ("q95_lower", "q95", "q95_upper"))
        assert np.all(lower <= q95) and np.all(q95 <= upper) and np.all(upper <= ds[f"max_sampled_{family}"].values[
            :, reachable]) and np.all(lower < upper)
    assert ds.attrs["seed"] == 3 and ds.attrs["n_draws"] == 100 and ds["platform_n1"].attrs["units"] == "rad"
    printed = capsys.readouterr().out
    assert "reachable: " in printed and "point estimate" not in printed   # 100 draws: q95 has its interval
    assert sorted(p.name for p in out.glob("*.png")) == sorted(f"workspace_map_{d}.png"
                                                               for d in ("x", "y", "z", "rx", "ry", "rz"))


def test_the_q95s_largest_pose_comes_with_its_interval_and_whether_it_is_resolved(smoke):
    """Review 63: on a mirror-symmetric robot 'where the q95 is largest' at 64 draws was noise, named from point
    estimates. The console gives the largest pose's interval and the poses whose interval reaches its lower end;
    with a pose made clearly larger, no other reaches it and the location is said to be resolved."""
    from pipeline.studies.workspace_map import GridAxis, map_table, workspace_map
    ds = workspace_map(smoke, (GridAxis("y", -0.05, 0.05, 5), GridAxis("z", -0.6, -0.4, 3)), 64, 0)
    q95, lower, upper = (ds[f"{k}_translation"].sel(translation="x").values for k in ("q95", "q95_lower", "q95_upper"))
    top = np.unravel_index(np.nanargmax(q95), q95.shape)
    others = int((upper >= lower[top]).sum()) - 1
    assert others > 0    # 64 draws on a symmetric robot: the intervals overlap
    line = next(ln for ln in map_table(ds).splitlines() if ln.startswith("  x: "))
    assert f"[{lower[top] * 1e3:.4g}, {upper[top] * 1e3:.4g}]" in line, line
    assert f"{others} other poses' intervals reach it" in line and "not resolved at n = 64" in line, line
    for name in ("q95", "q95_lower", "q95_upper"):   # one pose far above the rest
        ds[f"{name}_translation"].loc[dict(translation="x", platform_y=0.0, platform_z=-0.5)] = 1.0
    line = next(ln for ln in map_table(ds).splitlines() if ln.startswith("  x: "))
    assert line.endswith("at y = 0 mm, z = -500 mm; no other pose's interval reaches it: located at this n"), line


def test_the_heat_maps_are_legible_and_mask_the_unreachable(smoke):
    """tests/test_figures.py's legibility check on all six figures of a map with unreachable poses,
    whose grey cells are masked values of the colour mesh, explained in the legend."""
    from pipeline.analysis.map_plots import map_figures
    from pipeline.studies.workspace_map import GridAxis, map_table, workspace_map
    ds = workspace_map(smoke, (GridAxis("y", -0.05, 0.05, 4), GridAxis("z", -0.9, -0.35, 5)), 40, 2)
    figs = map_figures(ds)
    mesh = figs["workspace_map_x.png"].axes[0].collections[0]
    assert np.array_equal(np.ma.getmaskarray(mesh.get_array()).ravel(), ~ds["reachable"].values.astype(bool).ravel())
    assert "unreachable" in [t.get_text() for t in figs["workspace_map_x.png"].legends[0].get_texts()]
    assert figs["workspace_map_rz.png"].axes[1].get_xlabel() == "platform position y [mm]"
    # 40 draws: below the 59 of the q95's 95 % interval, the q95 panel and the table say what it is
    assert "q95 from 40 draws per pose: a point estimate" in figs["workspace_map_x.png"].axes[1].get_title()
    assert "point estimate" not in figs["workspace_map_x.png"].axes[0].get_title()
    assert map_table(ds).splitlines()[-1] == ("q95 from 40 draws per pose: a point estimate without its 95 % "
                                              "interval, which needs n >= 59 (-n)")
    _sibling("test_figures").assert_legible(figs)


def test_the_trajectory_is_cut_at_the_grids_edge_and_the_legend_says_so(smoke):
    """A grid narrower than the path: the axes stay on the grid's cells and the legend says the path leaves it;
    a grid that holds the path: the plain legend, the axes on the grid all the same."""
    from pipeline.analysis.map_plots import map_figures
    from pipeline.studies.workspace_map import GridAxis, workspace_map
    for half_width, cut in ((0.02, True), (0.06, False)):   # the smoke path's y spans +-0.05 m
        ds = workspace_map(smoke, (GridAxis("y", -half_width, half_width, 3), GridAxis("z", -0.5, -0.3, 3)), 8, 2)
        ax = map_figures(ds)["workspace_map_x.png"].axes[0]
        cell = 1e3 * half_width / 2   # mm: half of the 3 centres' spacing, half_width
        np.testing.assert_allclose(ax.get_xlim(), (-1e3 * half_width - cell, 1e3 * half_width + cell))
        np.testing.assert_allclose(ax.get_ylim(), (-550.0, -250.0))
        label = ax.get_legend_handles_labels()[1][0]
        assert ("cut at the grid's edge" in label) == cut, label
        plt.close("all")


def test_a_banded_scenes_heat_maps_keep_their_title_on_the_canvas(configs):
    """paper_tolerance's title lists the families drawn from size bands: it ran past both edges until
    the title was wrapped (review of 2026-11-27)."""
    from pipeline.analysis.map_plots import map_figures
    from rss6core import load_scene
    from pipeline.studies.workspace_map import GridAxis, workspace_map
    scene = load_scene(configs / "paper_tolerance.toml")
    ds = workspace_map(scene, (GridAxis("y", -0.05, 0.05, 3), GridAxis("z", -0.45, -0.35, 3)), 8, 0)
    figs = map_figures(ds)
    assert "spherical_B" in figs["workspace_map_z.png"]._suptitle.get_text()
    _sibling("test_figures").assert_legible(figs)


def test_the_map_file_reads_back_as_written(tmp_path, smoke):
    from pipeline.files.writing import write_netcdf
    from pipeline.studies.workspace_map import GridAxis, workspace_map
    ds = workspace_map(smoke, (GridAxis("y", -0.05, 0.05, 4), GridAxis("z", -0.9, -0.35, 5)), 40, 2)
    write_netcdf(ds, tmp_path / "m.nc")
    xr.testing.assert_identical(load_netcdf(tmp_path / "m.nc"), ds)
    assert np.isnan(ds["q95_lower_rotation"].values).all()   # 40 draws: no 95 % interval of the q95 below 59


@pytest.mark.slow   # compliance-checker's cf:1.10 suite twice: about 10 s
def test_the_map_file_is_cf(tmp_path, capsys):
    """No cf:1.10 error (tests/test_cf.py's cf_errors), and `compliance-checker --test=cf:1.10` exits 0
    at its default criteria (a warning fails it too), as tests/test_cf.py asks of every other kind."""
    import shutil
    import subprocess
    import sys
    path = _unreachable_map(tmp_path) / "workspace_map.nc"
    assert _cf_errors()(path) == []
    checker = Path(sys.executable).with_name("compliance-checker")
    checker = str(checker) if checker.exists() else shutil.which("compliance-checker")
    proc = subprocess.run([checker, "--test=cf:1.10", str(path)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-2000:]


def test_the_default_grid_spans_the_trajectory_and_the_same_seed_gives_the_same_map(paper):
    """The paper trajectory moves in y (50 mm) and z (80 mm): the default grid spans those, padded
    by 10 %, at the mean pose (n1 = n2 = 0); the q95 repeats exactly with the seed."""
    from pipeline.studies.workspace_map import GridAxis, default_grid, workspace_map
    y, z = default_grid(paper)
    assert (y.axis, z.axis, y.count, z.count) == ("y", "z", 21, 21)
    assert (y.low, y.high) == pytest.approx((-0.06, 0.06)) and (z.low, z.high) == pytest.approx((-0.483, -0.291))
    small = (GridAxis("y", -0.02, 0.02, 3), GridAxis("n1", -0.1, 0.1, 3))
    a, b = workspace_map(paper, small, 50, 1), workspace_map(paper, small, 50, 1)
    np.testing.assert_array_equal(a["q95_translation"].values, b["q95_translation"].values)
    assert float(a["platform_z"]) == pytest.approx(-0.387) and float(a["platform_n2"]) == pytest.approx(0, abs=1e-12)


def test_the_worst_case_takes_each_band_upper_end(configs, paper):
    """paper_tolerance's [tolerance] bands end at 0.37 mm (radial) and 0.35 mm (axial, C, B); the paper
    scene has no band and takes its nominal 0.25 mm; a [sampling] size_tolerance reaches 2 x nominal."""
    import dataclasses

    from rss6core import RELATIVE_BAND_REACH, load_scene
    banded = worst_case_sizes(load_scene(configs / "paper_tolerance.toml"))
    assert (banded.revolute_radial, banded.revolute_axial, banded.spherical_C, banded.spherical_B) == (
        0.37e-3, 0.35e-3, 0.35e-3, 0.35e-3)
    assert len(banded.from_band) == 4 and worst_case_sizes(paper).from_band == ()
    relative = dataclasses.replace(paper, sampling=dataclasses.replace(paper.sampling, size_tolerance=0.1))
    assert worst_case_sizes(relative).spherical_B == pytest.approx(RELATIVE_BAND_REACH * 0.25e-3)


def test_a_scene_with_uncertain_inputs_is_refused_in_one_line_before_any_work(tmp_path, capsys):
    """The map is the nominal geometry's clearance error: a manufacturing scene ends in one line, exit 2,
    and writes no folder."""
    out = tmp_path / "map"
    assert main(["map", "paper_manufacturing", "-n", "10", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "[uncertain.crank_length]" in err and "paper_manufacturing" in err
    assert not out.exists()


def test_a_grid_the_robot_reaches_nowhere_is_one_line_and_exit_2(tmp_path, capsys):
    """Not "reachable: 0 of 9 poses", exit 0 and empty heat maps (bad-input audit)."""
    from pipeline.cli import main
    out = tmp_path / "map"
    assert main(["map", "smoke", "--grid", "x:-2:-1:3", "--grid", "y:-2:-1:3", "-n", "4", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("rss6 map: error: --grid x:-2:-1:3 --grid y:-2:-1:3: the robot reaches none of its 9 poses; choose "
                   "a grid inside the workspace (rss6 check prints the trajectory's)") and not out.exists()
