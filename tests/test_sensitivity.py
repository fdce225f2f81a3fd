"""rss6 sensitivity: the uniforms-to-draw map against the core's draw, the Sobol' indices of the
quasi-static level against their closed form, the bootstrap intervals' measured coverage, and
the command (file, errors, reproducibility)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps

from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec
from pipeline.scenes.variant import scene_variant
from pipeline.studies.sensitivity import (JOINT_FAMILIES, clearance_draws_from_uniforms, clearance_inputs, designs,
                                          evaluate_statistics, sample_design, sobol_indices)
from pipeline.files.reading import load_netcdf
from pipeline.files.records import error_summaries
from pipeline.vocabulary import WINDOWS
from rss6core import parse_scene, prepare_level
from rss6core.clearance import draw_clearances, realization_rng
from rss6core.kinematics import rigid_motion
from rss6core.quasi_static import closure_matrix, quasi_static_error

T0 = 0.3   # s: the instant of the closed-form check


def _core_stream_uniforms(scene, seed: int, realization: int) -> np.ndarray:
    """The uniforms draw_clearances takes from realisation r's stream, laid out as the inputs:
    four blocks of six size uniforms, then radial magnitude, angle, axial, and per spherical
    family magnitude, polar and azimuth (the order of rss6core.clearance)."""
    inputs = clearance_inputs(scene)
    rng = realization_rng(seed, realization)
    u = np.zeros((1, len(inputs.names)))
    blocks = [("A", "radial_size"), ("A", "axial_size"), ("C", "size"), ("B", "size"),
              ("A", "radial_magnitude"), ("A", "radial_angle"), ("A", "axial"),
              ("C", "magnitude"), ("C", "polar"), ("C", "azimuth"),
              ("B", "magnitude"), ("B", "polar"), ("B", "azimuth")]
    for kind, what in blocks:
        values = rng.uniform(size=6)
        for leg in range(6):
            name = f"{kind}{leg + 1}_{what}"
            if name in inputs.names:
                u[0, inputs.names.index(name)] = values[leg]
    return u


@pytest.mark.parametrize("sampling", [{}, {"size_tolerance": 0.1, "direction": "paper",
                                           "axial_mean": 0.2}])
def test_uniforms_give_the_core_draw(paper_text, sampling):
    """Fed the uniforms of a realisation's stream, the map gives draw_clearances' draw exactly."""
    text = scene_variant(paper_text, {"sampling": sampling}) if sampling else paper_text
    scene = parse_scene(text)
    for r in (0, 5):
        mine = clearance_draws_from_uniforms(scene, clearance_inputs(scene),
                                             _core_stream_uniforms(scene, 3, r))[0]
        core = draw_clearances(scene, 3, r)
        for field in ("radial_size", "axial_size", "size_C", "size_B", "e_A", "e_C", "e_B"):
            np.testing.assert_allclose(getattr(mine, field), getattr(core, field), rtol=1e-13,
                                       atol=1e-18, err_msg=field)


def _truncated_normal(mean, std, low, high):
    return sps.truncnorm((low - mean) / std, (high - mean) / std, loc=mean, scale=std)


def closed_form_indices(scene, t0: float) -> np.ndarray:
    """S1 = ST (family, direction) of the quasi-static displacement error at t0.

    d = sum_l J_l e_l with J_l = G^-1[:, l] n_l^T and e_l = e_A,l + e_C,l - e_B,l; the families are
    independent, so Var(d_k) = sum_g sum_l (J_l Cov_g,l J_l^T)_kk and S_g = Var_g / Var.  Covariances:
    radial E[r^2]/2 on the plane (x_l, Z); axial Var(a) w w^T; spherical delta^2/9 I (k ~ U(0, 1),
    direction uniform on the sphere)."""
    G, n = closure_matrix(rigid_motion(scene, np.array([t0])))
    J = np.einsum("kl,li->lki", np.linalg.inv(G[0]), n[0])
    cl, law, geo = scene.clearance, scene.sampling, scene.geometry
    dr, da = cl.revolute_radial, cl.revolute_axial
    radial = _truncated_normal(law.radial_mean * dr, law.radial_std * dr, 0.0, dr).moment(2)
    axial = _truncated_normal(law.axial_mean * da, law.axial_std * da, -da, da).var()
    px = np.stack([np.cos(geo.base_angles), np.sin(geo.base_angles), 0 * geo.base_angles], -1)
    pz = np.array([0.0, 0.0, 1.0])
    covs = [radial / 2 * (np.einsum("li,lj->lij", px, px) + np.outer(pz, pz)),
            axial * np.einsum("li,lj->lij", geo.w, geo.w),
            np.broadcast_to(cl.spherical_C ** 2 / 9 * np.eye(3), (6, 3, 3)),
            np.broadcast_to(cl.spherical_B ** 2 / 9 * np.eye(3), (6, 3, 3))]
    var = np.stack([np.einsum("lki,lij,lkj->k", J, c, J) for c in covs])
    return var / var.sum(axis=0)


def _instant_error(scene, inputs, u: np.ndarray, t0: float) -> np.ndarray:
    """(rows, 6) quasi-static displacement error at t0 from the core, per row of uniforms."""
    dt = 1e-3
    motion = rigid_motion(scene, np.array([t0 - dt, t0, t0 + dt]))
    return np.stack([quasi_static_error(scene, motion, d)[0][1]
                     for d in clearance_draws_from_uniforms(scene, inputs, u)])


def test_closed_form_is_not_trivial(paper):
    """The closed form separates the families (or the check below could not fail)."""
    S = closed_form_indices(paper, T0)
    np.testing.assert_allclose(S.sum(axis=0), 1.0)
    assert S[0].min() > 0.35 and S[1].max() < 0.02 and S[2].min() > 0.25


def test_quasi_static_indices_match_the_closed_form(paper):
    """At an instant the quasi-static error is linear in the eccentricities, so S1 = ST = Var_g / Var
    in closed form.  The 48 cells (S1, ST x 4 families x 6 directions) from N = 1024 (6144 core
    evaluations) lie within their 95 % bootstrap intervals: coverage was measured at 94-98 % (slow
    test below), so 1-2 of 48 may lie outside; at most 5 are allowed (more happens with
    probability 3 % at 95 % coverage, 0.1 % at 97.5 %, were the cells independent), none by more
    than half an interval width beyond its bound, and every interval is narrower than 0.22 (0.15 at
    the label's own z, 1.43x narrower than the widened one; a swapped or misweighted family fails)."""
    inputs = clearance_inputs(paper)
    design = designs(inputs, False)[0]
    u = sample_design(design, 1024, seed=1)
    values = sobol_indices(design, _instant_error(paper, inputs, u, T0), 0.95, seed=1).values
    S = closed_form_indices(paper, T0)[None]
    est, lo, hi = values[:, 0], values[:, 1], values[:, 2]
    outside = (S < lo) | (S > hi)
    assert outside.sum() <= 5, np.argwhere(outside)
    assert np.all(np.abs(S - est) <= 1.5 * (hi - lo) / 2)
    assert np.all(hi - lo < 0.22)


@pytest.mark.slow
def test_bootstrap_intervals_reach_their_confidence_on_the_linear_model(paper):
    """Coverage of the 95 % bootstrap intervals at N = 64 (the smallest N the command accepts) over
    200 independent designs (sampling and bootstrap seeds), on the closed-form case: at least 93 %
    (nominal minus 2 points) for S1 and for ST.  Measured with the widened z: S1 99.3 %, ST 99.1 %;
    at N = 256, 99.9 % and 99.6 % (at the label's own z: 94.2 %, 96.1 %; 97.7 %, 97.5 %).  The model
    is evaluated through its Jacobian (the test above checks the core)."""
    G, n = closure_matrix(rigid_motion(paper, np.array([T0])))
    J = np.einsum("kl,li->lki", np.linalg.inv(G[0]), n[0])
    inputs = clearance_inputs(paper)
    design = designs(inputs, False)[0]
    S = closed_form_indices(paper, T0)[None]
    inside = []
    for rep in range(200):
        u = sample_design(design, 64, seed=rep)
        e = np.stack([d.e_A + d.e_C - d.e_B for d in clearance_draws_from_uniforms(paper, inputs, u)])
        values = sobol_indices(design, np.einsum("lki,rli->rk", J, e), 0.95, seed=rep).values
        inside.append((values[:, 1] <= S) & (S <= values[:, 2]))
    coverage = np.mean(inside, axis=(0, 2, 3))
    assert coverage.min() >= 0.93, coverage


def _max_over_time(u: np.ndarray) -> np.ndarray:
    """(rows,) max over 50 instants of |sum_i c_i(t) e_i|, e = 2 u - 1: 24 inputs in 4 groups of 6
    (scales 1, 0.15, 0.8, 0.7), the clearance response's shape at the quasi-static level (the output
    of benchmarks/sobol_coverage.py)."""
    phase = np.random.default_rng(5).uniform(0.0, 2.0 * np.pi, 24)
    t = np.linspace(0.0, 2.0 * np.pi, 50)
    coef = np.repeat((1.0, 0.15, 0.8, 0.7), 6)[:, None] * np.cos(t[None, :] + phase[:, None])
    return np.abs((2.0 * u - 1.0) @ coef).max(axis=1)


@pytest.mark.slow   # about 2 minutes
def test_widened_bootstrap_intervals_reach_their_label_on_a_maximum_over_time():
    """On a maximum over time, the statistic rss6 ranks, the bootstrap's own 95 % z covers the truth
    (N = 2^16) in under 95 % of 500 designs at N = 64 for some group (88.6-93.4 % measured); the
    widened z (SOBOL_WIDENING) in at least 95 % for every group and index (96.2-99.2 %).  The seeds
    are benchmarks/sobol_coverage.py's, so these are its numbers."""
    from SALib.sample import sobol
    from pipeline.studies.sensitivity import SOBOL_WIDENING, Design
    names = [f"u{i}" for i in range(24)]
    problem = {"num_vars": 24, "names": names, "bounds": [[0.0, 1.0]] * 24,
               "groups": [f"g{i // 6}" for i in range(24)]}
    design = Design("families", tuple(f"g{k}" for k in range(4)), problem)

    def indices(n, seed, widening):
        u = sobol.sample(problem, n, calc_second_order=False, scramble=True, seed=seed)
        return sobol_indices(design, _max_over_time(u)[:, None], 0.95, seed, widening=widening).values[..., 0]

    truth = indices(2 ** 16, 123, SOBOL_WIDENING)[:, 0]
    for widening, reaches in ((SOBOL_WIDENING, True), (1.0, False)):
        hits = sum((v[:, 1] <= truth) & (truth <= v[:, 2]) for v in (indices(64, 1000 + k, widening)
                                                                      for k in range(500)))
        assert (hits.min() / 500 >= 0.95) == reaches, hits / 500


def test_evaluations_do_not_depend_on_chunking(smoke):
    spec = EnsembleSpec(smoke.source_text, "smoke", "quasi-static", "newmark", 1e-3, 4, 0)
    inputs = clearance_inputs(smoke)
    u = sample_design(designs(inputs, False)[0], 8, seed=0)[:20]
    one = evaluate_statistics(spec, inputs, u, chunk=20)
    many = evaluate_statistics(spec, inputs, u, chunk=3)
    np.testing.assert_array_equal(one, many)


def test_window_statistics_are_taken_over_the_windows_samples(smoke):
    """--window: the steady maxima are the maxima over t >= steady_after_s of each evaluation's own
    history, the whole-run ones those of before (error_summaries) and the larger of startup and steady."""
    spec = EnsembleSpec(smoke.source_text, "smoke", "quasi-static", "newmark", 1e-3, 4, 0)
    inputs = clearance_inputs(smoke)
    u = sample_design(designs(inputs, False)[0], 8, seed=0)[:5]
    stats = {w: evaluate_statistics(spec, inputs, u, window=w) for w in WINDOWS}
    level = prepare_level(smoke, "quasi-static", "newmark", 1e-3, 4)
    results = level.simulate_draws(clearance_draws_from_uniforms(smoke, inputs, u))
    sim = smoke.simulation
    steady = (smoke.times >= sim.steady_after) & (smoke.times >= sim.settle_time)
    assert 0 < steady.sum() < len(steady)
    for r, result in enumerate(results):
        np.testing.assert_array_equal(stats["steady"][r, 0, 0], np.abs(result.displacement)[steady].max(0))
        np.testing.assert_array_equal(stats["whole"][r], np.stack(error_summaries(result, sim.settle_time)))
    np.testing.assert_array_equal(stats["whole"][:, 0], np.maximum(stats["startup"][:, 0], stats["steady"][:, 0]))
    assert not np.array_equal(stats["startup"], stats["steady"])


def test_an_empty_window_is_refused_before_any_work(smoke, tmp_path, capsys):
    config = tmp_path / "nostartup.toml"
    config.write_text(smoke.source_text.replace("[simulation]\n", "[simulation]\nsteady_after_s = 0.0\n", 1))
    out = tmp_path / "x.nc"
    code = main_code(["sensitivity", str(config), "--window", "startup", "-o", str(out), "--no-plots"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "--window startup" in err and "startup window is empty" in err, err
    assert not out.exists()


def test_a_scene_without_clearances_is_refused_before_any_work(smoke, tmp_path, capsys):
    """All four clearance sizes 0: every evaluation is the same, so every index would be 0/0."""
    zero = {k: 0.0 for k in ("revolute_radial_m", "revolute_axial_m", "spherical_C_m", "spherical_B_m")}
    config = tmp_path / "tight.toml"
    config.write_text(scene_variant(smoke.source_text, {"clearance": zero}, smoke.source_path))
    out = tmp_path / "x.nc"
    code = main_code(["sensitivity", str(config), "--model", "quasi-static", "-o", str(out), "--no-plots"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "every [clearance] size is 0" in err, err
    assert not out.exists()


@pytest.fixture(scope="module")
def sobol_file(tmp_path_factory, configs):
    path = tmp_path_factory.mktemp("sens") / "s.nc"
    assert main(["sensitivity", str(configs / "smoke.toml"), "-n", "64", "--per-joint", "--workers", "1",
                 "-o", str(path), "--no-plots"]) == 0
    return path


def test_sensitivity_file(sobol_file):
    ds = load_netcdf(sobol_file)
    da = ds["max_abs_error_sobol"]
    assert da.dims == ("index", "bound", "group", "quantity", "direction")
    assert list(ds["index"].values) == ["S1", "ST"]
    assert list(ds["bound"].values) == ["estimate", "lower", "upper"]
    assert list(ds["group"].values)[:4] == list(JOINT_FAMILIES) and ds.sizes["group"] == 22
    assert "bootstrap" in ds.attrs["interval_method"] and ds.attrs["confidence"] == 0.95
    assert ds.attrs["window"] == "whole" and da.attrs["analysis_window"] == "whole run"
    assert ds.attrs["evaluations_families"] == 64 * 6 and ds.attrs["evaluations_joints"] == 64 * 20
    est, lo, hi = (da.sel(bound=b).values for b in ("estimate", "lower", "upper"))
    assert np.all(lo <= hi) and np.isfinite(est).all()
    # the bounds clipped to [0, 1], where every index lies (the estimates not: their noise is noted)
    assert np.all(lo >= 0) and np.all(hi <= 1) and "clipped to [0, 1]" in ds.attrs["interval_method"]
    assert np.all(lo <= np.clip(est, 0, 1)) and np.all(np.clip(est, 0, 1) <= hi)


def test_sensitivity_is_reproducible_across_workers(sobol_file, configs, tmp_path):
    """Same seed, same numbers: two dask workers in chunks give the in-process family indices
    (each design has its own streams, so the family design does not depend on --per-joint)."""
    path = tmp_path / "s2.nc"
    assert main(["sensitivity", str(configs / "smoke.toml"), "-n", "64", "--workers", "2",
                 "-o", str(path), "--no-plots"]) == 0
    a, b = load_netcdf(sobol_file).sel(group=list(JOINT_FAMILIES)), load_netcdf(path)
    for name in ("max_abs_error_sobol", "mean_abs_error_sobol"):
        np.testing.assert_array_equal(a[name].values, b[name].values)


@pytest.mark.parametrize("argv, message", [
    (["-n", "100"], "-n 100: the base sample must be a power of 2"),
    (["-n", "32"], "-n 32: the base sample must be a power of 2 of at least 64"),
    (["--model", "paper"], "invalid choice: 'paper'"),
    (["--window", "late"], "invalid choice: 'late'"),
])
def test_bad_requests_get_one_line(argv, message, configs, tmp_path, capsys):
    out = tmp_path / "x.nc"
    code = main_code(["sensitivity", str(configs / "smoke.toml"), "-o", str(out), "--no-plots"] + argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_existing_output_is_refused(sobol_file, configs, capsys):
    """Another request onto a finished file (its -n and --per-joint differ) is refused, naming what differs."""
    before = sobol_file.read_bytes()
    assert main(["sensitivity", str(configs / "smoke.toml"), "-o", str(sobol_file)]) == 2
    err = capsys.readouterr().err
    assert "holds the answer to another rss6 sensitivity request" in err and "-n 64 there, 1024 now" in err, err
    assert sobol_file.read_bytes() == before


def main_code(argv) -> int:
    """main's exit code, also when argparse exits."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def test_the_joint_table_lists_the_largest_joints_from_the_file(sobol_file):
    """--per-joint: per quantity and direction the three joints of largest ST, largest first, with
    the intervals the file holds; no table without the joint design."""
    from pipeline.studies.sensitivity_table import format_joints
    ds = load_netcdf(sobol_file)
    lines = format_joints(ds).splitlines()
    assert len(lines) == 2 + 18 and "of 18; all in the file" in lines[0]
    st = ds["max_abs_error_sobol"].sel(index="ST", quantity="velocity", direction="y",
                                       group=[g for g in ds["group"].values if g not in JOINT_FAMILIES])
    est = st.sel(bound="estimate")
    first = str(est["group"].values[int(np.argmax(est.values))])
    row = [s for s in lines if s.startswith("velocity     y   ")][0]
    lo, hi = (float(st.sel(group=first, bound=b)) for b in ("lower", "upper"))
    assert row[17:].startswith(f"{first} {float(est.sel(group=first)):.3f} [{lo:.3f},{hi:.3f}]"), row
    assert format_joints(ds.sel(group=list(JOINT_FAMILIES))) == ""


def test_total_estimates_outside_zero_one_get_a_note_naming_the_worst(sobol_file):
    """No index lies outside [0, 1], but an estimate at small N can: the table says so and names the
    estimate farthest out; with every estimate inside, no note."""
    from pipeline.studies.sensitivity_table import format_sensitivity
    ds = load_netcdf(sobol_file)
    inside = ds.assign(max_abs_error_sobol=ds["max_abs_error_sobol"].clip(0, 1))
    assert "ST estimates lie outside" not in format_sensitivity(inside)
    # the label comes with its coverage on a maximum over time (benchmarks/sobol_coverage.py)
    assert format_sensitivity(inside).splitlines()[0].endswith(
        "[95 % bootstrap interval, z widened: >= 96 % measured on a maximum over time, docs/ensembles.md]")
    st = inside["max_abs_error_sobol"]
    st.loc[dict(index="ST", bound="estimate", group="spherical_B", quantity="velocity", direction="rz")] = 1.4
    st.loc[dict(index="ST", bound="estimate", group="revolute_axial", quantity="velocity", direction="x")] = -0.1
    note = [s for s in format_sensitivity(inside.assign(max_abs_error_sobol=st)).splitlines() if "outside" in s][0]
    assert note.startswith("note: 2 ST estimates lie outside [0, 1] (e.g. 1.400, spherical_B on velocity rz)")
    assert "N = 64" in note


def test_the_largest_family_is_named_with_its_overlap():
    import xarray as xr
    from pipeline.studies.sensitivity_table import _dominant

    def cell(est, half):
        est = np.asarray(est)
        return xr.DataArray(np.stack([est, est - half, est + half]), dims=("bound", "group"),
                            coords={"bound": ["estimate", "lower", "upper"], "group": list(JOINT_FAMILIES)})
    assert _dominant(cell([0.7, 0.02, 0.5, 0.4], 0.05)) == "revolute_radial"
    assert _dominant(cell([0.5, 0.02, 0.7, 0.65], 0.05)) == "spherical_C (overlaps spherical_B)"
    assert _dominant(cell([np.nan] * 4, 0.05)) == "-"


@pytest.mark.parametrize("model", ["rigid", "elastic", "paper"])
def test_a_level_not_a_function_of_one_draw_is_refused_with_the_reasons_from_the_level_table(model):
    """Through the API (the command offers only the accepted levels as choices): the accepted levels
    and the reasons for the others are read from the core's level table, in the words they had."""
    from pipeline.studies.sensitivity import LEVELS, SensitivityError, sensitivity
    assert LEVELS == ("quasi-static", "contact")
    spec = EnsembleSpec("", "smoke", model, "newmark", 1e-3, 4, 0)
    with pytest.raises(SensitivityError) as caught:
        sensitivity(spec, 64)
    assert str(caught.value) == (f"--model {model}: Sobol' indices need a level whose error is a function of "
                                 "one clearance draw (quasi-static, contact); the paper level redraws the "
                                 "clearances every step, rigid and elastic have none")


def test_families_of_fixed_sizes_are_said_to_draw_eccentricities_not_sizes(sobol_file):
    """On a scene of fixed clearance sizes (smoke, paper) the table read 'revolute_radial' as the clearance, though
    its inputs are the eccentricities inside it: the header and an 'inputs' line now say so, and point to the scenes
    that draw sizes; a family whose group holds its sizes (a [tolerance.*] band) is not named."""
    from pipeline.studies.sensitivity_table import format_sensitivity
    ds = load_netcdf(sobol_file)
    lines = format_sensitivity(ds).splitlines()
    assert "by joint family (eccentricity inside a fixed size: see 'inputs' below)," in lines[0]
    inputs = [s for s in lines if s.startswith("inputs: ")]
    assert len(inputs) == 1 and inputs[0].startswith(f"inputs: {', '.join(JOINT_FAMILIES)} (and their joints")
    assert "drawn eccentricities inside each clearance" in inputs[0] and "paper_tolerance" in inputs[0]
    sized = ds["group_inputs"].values.copy()
    sized[:2] = [f"A1_radial_size {sized[0]}", f"A1_axial_size {sized[1]}"]   # the revolute families banded
    lines = format_sensitivity(ds.assign(group_inputs=(("group",), sized))).splitlines()
    assert [s for s in lines if s.startswith("inputs: ")][0].startswith("inputs: spherical_C, spherical_B (")
    sized[2:4] = [f"C1_size {sized[2]}", f"B1_size {sized[3]}"]
    lines = format_sensitivity(ds.assign(group_inputs=(("group",), sized))).splitlines()
    assert not any(s.startswith("inputs: ") for s in lines) and "eccentricity" not in lines[0]


def test_bounds_are_clipped_to_zero_one_with_a_note(paper):
    """A total index lies in [0, 1], so the bootstrap's normal interval estimate -+ z sd is clipped there (review
    63b #11: 0.674 [-0.062, 1.409] was printed); the estimate is not, and the table says so."""
    from pipeline.studies.sensitivity import sobol_indices
    design = designs(clearance_inputs(paper), False)[0]
    u = sample_design(design, 64, 0)
    y = np.random.default_rng(0).normal(size=(len(u), 1)) + u[:, :1]   # mostly noise: wide intervals
    values = sobol_indices(design, y, 0.95, 0).values
    assert np.nanmin(values[:, 1:]) >= 0 and np.nanmax(values[:, 1:]) <= 1
    assert (values[:, 1:] == 0).any() or (values[:, 1:] == 1).any()   # some bound was clipped


def test_the_table_says_when_bounds_are_clipped(sobol_file):
    from pipeline.studies.sensitivity_table import format_sensitivity
    ds = load_netcdf(sobol_file)
    st = ds["max_abs_error_sobol"].clip(0.01, 0.99)
    assert "clipped to [0, 1]" not in format_sensitivity(ds.assign(max_abs_error_sobol=st))
    st.loc[dict(index="ST", bound="upper", group="spherical_B", quantity="velocity", direction="rz")] = 1.0
    assert "note: interval bounds are clipped to [0, 1]" in format_sensitivity(ds.assign(max_abs_error_sobol=st))


def test_a_label_other_than_95_says_its_coverage_was_not_measured(configs, tmp_path, capsys):
    """The coverage was measured at 95 % only (benchmarks/sobol_coverage.py): at 90 % the table head, a note and the
    file say so, and the file's interval_coverage names the run's label and widened level (review 63b #2)."""
    from pipeline.studies.sensitivity import COVERAGE_NOTE, SHORT_COVERAGE, interval_coverage
    path = tmp_path / "s90.nc"
    assert main(["sensitivity", str(configs / "smoke.toml"), "-n", "64", "--workers", "1", "--no-plots",
                 "--confidence", "0.9", "-o", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = [s for s in lines if s.startswith("total Sobol'")][0]
    assert SHORT_COVERAGE not in head and head.endswith("[90 % bootstrap interval, z widened, coverage measured "
                                                        "at 95 % only (docs/ensembles.md)]"), head
    assert any(s.startswith("note: 90 % intervals: coverage measured at 95 % only") for s in lines)
    ds = load_netcdf(path)
    assert ds.attrs["interval_coverage"].startswith("90 % intervals, z at the level 1 - SOBOL_WIDENING "
                                                    "(1 - confidence) (99 %): coverage measured at 95 % only")
    assert "for a 90 % label" in ds.attrs["interval_method"]
    assert interval_coverage(0.95) == COVERAGE_NOTE


def test_a_drawn_start_and_unresolved_outputs_are_said(sobol_file):
    """Contact level (review 63b #5): on the whole or startup window with a drawn start, the drawn-start note
    rss6 stats prints (analysis.stats.level_notes); where the outputs' spread is within the level's resolution
    (analysis.resolution, the plots' test), the indices are noise: a note, and no largest family for those rows."""
    from pipeline.analysis.resolution import resolutions
    from pipeline.analysis.stats import level_notes
    from pipeline.studies.sensitivity_table import NOISE, format_joints, format_sensitivity
    ds = load_netcdf(sobol_file)
    table = format_sensitivity(ds)
    assert NOISE not in table and "numerical noise" not in table and "drawn start" not in table
    assert (ds["max_abs_error_spread"] > ds["max_abs_error_resolution"]).all()   # quasi-static: all resolved
    contact = ds.assign_attrs(model="contact", contact_start="drawn")
    drawn = level_notes(contact.attrs, {"displacement"}, {"whole"})
    assert drawn and f"note: {drawn[0]}" in format_sensitivity(contact).splitlines()
    assert "drawn start" not in format_sensitivity(contact.assign_attrs(window="steady"))
    spread = contact["max_abs_error_spread"].copy()
    spread.loc[dict(quantity="acceleration")] = 0.01 * contact["max_abs_error_resolution"].sel(quantity="acceleration")
    lines = format_sensitivity(contact.assign(max_abs_error_spread=spread)).splitlines()
    rows = [s for s in lines if s.startswith("acceleration ")]
    assert len(rows) == 6 and all(s.endswith(NOISE) for s in rows)
    assert not any(s.endswith(NOISE) for s in lines if s.startswith("displacement "))
    note = [s for s in lines if "numerical noise" in s]
    assert len(note) == 1 and note[0].startswith("note: 6 rows (acceleration x, acceleration y")
    assert f"than the contact level resolves ({resolutions(contact, 'acceleration')['x'].source};" in note[0]
    joints = format_joints(contact.assign(max_abs_error_spread=spread)).splitlines()
    assert all("noise" in s for s in joints if s.startswith("acceleration "))


def test_the_spread_test_is_the_plots(smoke):
    """The file's spread and resolution per output: round-off at the quasi-static level (pipeline.analysis.resolution
    via the sensitivity file's attributes), so an output that varies by 1e-12 relative is unresolved."""
    from pipeline.studies.sensitivity import _spread_variables
    from pipeline.studies.sensitivity_table import unresolved_outputs
    import xarray as xr
    stats = np.random.default_rng(1).uniform(1e-4, 2e-4, size=(64, 2, 3, 6))
    stats[:, 0, 0, 2] = 1e-4 * (1 + 1e-12 * np.arange(64))
    attrs = {"model": "quasi-static", "scene_toml": smoke.source_text}
    data = _spread_variables(attrs, stats)
    ds = xr.Dataset(data, coords={"quantity": ["displacement", "velocity", "acceleration"],
                                  "direction": ["x", "y", "z", "rx", "ry", "rz"]})
    noise = unresolved_outputs(ds)
    assert bool(noise.sel(quantity="displacement", direction="z")) and int(noise.sum()) == 1
