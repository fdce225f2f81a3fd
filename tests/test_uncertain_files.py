"""Uncertain inputs through the pipeline: the ensemble file records every draw, reproducibly, and the
commands list them or refuse a level that cannot take them."""
import numpy as np
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec, ensemble, run_chunk
from pipeline.ensemble.sampler import QMCDesign
from pipeline.files.check import check_ensemble
from pipeline.files.reading import load_netcdf
from pipeline.files.schema import EnsembleFileError
from pipeline.files.writing import write_netcdf
from rss6core import parse_scene, uniform_dimension
from rss6core.uncertain import inputs_from_uniforms

from .test_cf import cf_errors

TABLES = """
[uncertain.crank]
parameter = "geometry.crank_length_m"
each = "leg"
law = "uniform"
low_m = -0.1e-3
high_m = 0.1e-3

[uncertain.zero]
parameter = "geometry.actuator_offsets_deg"
each = "leg"
law = "triangular"
low_deg = -0.02
mode_deg = 0.0
high_deg = 0.01

[uncertain.mass]
parameter = "platform.mass_kg"
law = "lognormal"
sigma = 0.1
"""


@pytest.fixture(scope="module")
def text(configs):
    return (configs / "smoke.toml").read_text() + TABLES


def _spec(text, model="quasi-static", seed=0, replicates=None):
    return EnsembleSpec(text, "u.toml", model, "newmark", 1e-3, 4, seed, "summary", qmc_replicates=replicates)


def test_the_file_records_every_draw_with_names_units_and_laws_and_is_cf(text, tmp_path):
    ds = run_chunk(_spec(text), [0, 1, 2])
    var = ds["uncertain_input"]
    assert var.dims == ("realization", "input") and var.shape == (3, 13)
    assert list(ds["input"].values[:2]) == ["crank[leg 1]", "crank[leg 2]"] and ds["input"].values[-1] == "mass"
    assert list(ds["input_units"].values[[0, 6, 12]]) == ["m", "rad", "1"]
    assert ds["input_law"].values[12] == "lognormal factor (sigma=0.1, median=1.0)"
    assert ds["input_parameter"].values[6] == "geometry.actuator_offsets_deg"
    lo, hi = np.radians([-0.02, 0.01])
    assert (np.abs(var.values[:, :6]) <= 1e-4).all()
    assert (var.values[:, 6:12] >= lo).all() and (var.values[:, 6:12] <= hi).all()
    path = tmp_path / "u.nc"
    write_netcdf(ds, path)
    assert cf_errors(path) == []
    xr.testing.assert_identical(load_netcdf(path), ds)


@pytest.mark.parametrize("model, steps", [("quasi-static", None), ("paper", 201)])
def test_qmc_draws_take_the_points_last_coordinates(text, model, steps):
    """After the clearance draw's coordinates: one draw's, or the paper level's 201 steps'."""
    scene = parse_scene(text)
    ds = run_chunk(_spec(text, model, replicates=4), [5])
    u = QMCDesign(0, 4)(5, uniform_dimension(steps, scene))
    assert u.size == uniform_dimension(steps) + 13
    want = inputs_from_uniforms(scene.uncertain, u[uniform_dimension(steps):]).values
    assert np.array_equal(ds["uncertain_input"].values[0], want)


def test_same_seed_same_file_for_one_and_two_workers(text, tmp_path):
    files = []
    for workers, chunk in ((1, 5), (2, 3)):
        out = tmp_path / f"w{workers}.nc"
        ensemble(_spec(text, "rigid", seed=9), 10, out, workers=workers, chunk=chunk, progress=False)
        files.append(load_netcdf(out))
    xr.testing.assert_identical(files[0], files[1])
    assert np.unique(files[0]["uncertain_input"].values[:, 0]).size == 10
    assert (files[0]["max_abs_error"].sel(window="whole", quantity="displacement") > 1e-6).all()


def test_a_zero_width_law_gives_the_nominal_scenes_file_data(configs):
    nominal = (configs / "smoke.toml").read_text()
    zero = nominal + '[uncertain.c]\nparameter = "geometry.rod_length_m"\nlaw = "normal"\nstd_m = 0.0\n'
    a, b = run_chunk(_spec(nominal), [0, 1, 2, 3]), run_chunk(_spec(zero), [0, 1, 2, 3])
    for name in ("max_abs_error", "mean_abs_error", "clearance_size", "eccentricity", "status"):
        assert np.array_equal(a[name].values, b[name].values), name
    assert not b["uncertain_input"].values.any()


def test_the_file_check_refuses_draws_that_do_not_fit_the_scene(text, configs):
    ds = run_chunk(_spec(text), [0, 1])
    check_ensemble(ds, "f.nc")
    bad = ds.copy(deep=True)
    bad["uncertain_input"][1, 3] = 2e-4          # outside the uniform's [-0.1, 0.1] mm
    with pytest.raises(EnsembleFileError, match=r"f.nc: uncertain_input crank\[leg 4\] of realisation 1 is"):
        check_ensemble(bad, "f.nc")
    foreign = ds.assign_attrs(scene_toml=(configs / "smoke.toml").read_text())
    with pytest.raises(EnsembleFileError, match="holds uncertain_input, but scene_toml has no"):
        check_ensemble(foreign, "f.nc")
    with pytest.raises(EnsembleFileError, match="no variable uncertain_input"):
        check_ensemble(ds.drop_vars(["uncertain_input", "input", "input_units", "input_law", "input_parameter"]),
                       "f.nc")


def test_check_lists_the_inputs(text, tmp_path, capsys):
    scene = tmp_path / "u.toml"
    scene.write_text(text)
    assert main(["check", str(scene)]) == 0
    out = capsys.readouterr().out
    assert ("uncertain input crank: geometry.crank_length_m, each leg (6 draws), uniform deviation "
            "(low_m=-0.0001, high_m=0.0001)") in out
    assert "uncertain input mass: platform.mass_kg, each one (1 draws), lognormal factor" in out


def test_drawn_clearance_sizes_are_the_files_sizes_in_an_ensemble_and_a_sensitivity_design(text):
    """An [uncertain] clearance size: the file's clearance_size is the drawn size (nominal + input), and the
    sensitivity design's draws take the sizes of its rows' inputs."""
    from pipeline.studies.sensitivity import clearance_draws_from_uniforms, clearance_inputs
    sized = text + ('\n[uncertain.radial]\nparameter = "clearance.revolute_radial_m"\neach = "joint"\n'
                    'law = "uniform"\nlow_m = -2e-5\nhigh_m = 2e-5\n')
    ds = run_chunk(_spec(sized), [0, 1])
    drawn = ds["uncertain_input"].sel(input=[f"radial[joint {i}]" for i in range(1, 7)]).values
    sizes = ds["clearance_size"].sel(joint=[f"A{i}" for i in range(1, 7)]).transpose("realization", ...).values
    assert np.array_equal(sizes, 0.25e-3 + drawn)
    scene = parse_scene(sized)
    inputs = clearance_inputs(scene)
    u = np.random.default_rng(0).random((3, len(inputs.names)))
    given = [inputs_from_uniforms(scene.uncertain, row[len(inputs.names) - inputs.uncertain:]) for row in u]
    for draw, g in zip(clearance_draws_from_uniforms(scene, inputs, u, given), given, strict=True):
        assert np.array_equal(draw.radial_size, 0.25e-3 + g.of("radial"))


def test_an_elastic_ensemble_of_realised_robots_records_the_inputs_and_differs_per_realisation(text, tmp_path):
    """The elastic level on realised robots: the file holds every drawn input, and the realisations'
    errors differ (their geometric errors differ), reproducibly."""
    ds = run_chunk(_spec(text, "elastic"), [0, 1, 2])
    assert ds["uncertain_input"].shape == (3, 13)
    again = run_chunk(_spec(text, "elastic"), [1, 2])
    assert ds.attrs["model"] == "elastic"
    assert np.array_equal(ds["uncertain_input"].values[1:], again["uncertain_input"].values)
    error = ds["max_abs_error"].transpose("realization", ...).values
    assert np.array_equal(error[1:], again["max_abs_error"].transpose("realization", ...).values)
    assert np.abs(error[0] - error[1]).max() > 1e-6     # m: 10-100 um geometric errors differ


def test_a_contact_ensemble_of_realised_robots_differs_per_realisation_far_beyond_the_solver(text):
    """The contact level on realised robots (lengths, offsets, payload) from the static equilibrium,
    where the nominal robot's realisations are all the same run: every drawn input in the file,
    chunking-independent rows, and steady-window maxima that differ from realisation to realisation
    by far more than the solver's 10 nm local tolerance."""
    text = text.replace("[simulation]", '[simulation]\ncontact_start = "equilibrium"', 1)
    sim = parse_scene(text).simulation

    def spec(scene):
        return EnsembleSpec(scene, "u.toml", "contact", sim.contact_integrator, sim.contact_time_step, 4, 0, "summary")

    ds, again = run_chunk(spec(text), [0, 1, 2]), run_chunk(spec(text), [2])
    alike = run_chunk(spec(text.split("[uncertain.crank]")[0]), [0, 1, 2])
    same = alike["max_abs_error"].sel(window="steady", quantity="displacement").transpose("realization", ...).values
    assert np.abs(same - same[0]).max() < 1e-8
    assert ds["uncertain_input"].shape == (3, 13) and (ds["status"] == "finished").all()
    check_ensemble(ds, "f.nc")
    steady = ds["max_abs_error"].sel(window="steady", quantity="displacement").transpose("realization", ...).values
    assert np.array_equal(steady[2], again["max_abs_error"].sel(window="steady", quantity="displacement")
                          .transpose("realization", ...).values[0])
    spread = steady.max(0) - steady.min(0)
    assert spread[:3].min() > 1e3 * 1e-8     # m: at least 10 um in every translation, against 10 nm


def test_sobol_indices_by_input_follow_the_physics(configs):
    """Zero clearances: the quasi-static error is the geometric error of the crank lengths alone, so
    their total index is 1 (within 6 bootstrap standard deviations, six directions at once), and
    the platform mass, which the level does not use, and every clearance family get exactly 0."""
    from scipy.stats import norm

    from pipeline.studies.sensitivity import SOBOL_WIDENING, sensitivity
    text = (configs / "smoke.toml").read_text()
    for key in ("revolute_radial_m", "revolute_axial_m", "spherical_C_m", "spherical_B_m"):
        text = text.replace(f"{key} = 0.25e-3", f"{key} = 0.0")
    text += (TABLES.split("[uncertain.zero]")[0]
             + '[uncertain.mass]\nparameter = "platform.mass_kg"\nlaw = "uniform"\nlow_kg = 0.0\nhigh_kg = 0.5\n')
    ds = sensitivity(_spec(text), 64, workers=1)
    st = ds["max_abs_error_sobol"].sel(index="ST", quantity="displacement")
    crank = st.sel(group="crank")
    z = norm.ppf(1 - SOBOL_WIDENING * 0.05 / 2)                    # the interval's half-width over sd
    est, lower, upper = (crank.sel(bound=b) for b in ("estimate", "lower", "upper"))
    sd = np.maximum(est - lower, upper - est) / z   # the bounds are clipped to [0, 1]: the unclipped half
    assert (abs(est - 1) <= 6 * sd).all() and (sd < 0.15).all()
    for group in ("mass", "revolute_radial", "spherical_B"):
        assert not st.sel(group=group, bound="estimate").any()


def test_a_budget_of_realised_robots_is_a_measured_sweep(text, tmp_path, capsys):
    """Their geometric error does not scale with the clearances, so the budget sweeps: its answer
    passes, a scale within 5 % above fails; a limit below the geometric error alone (z q50 about
    0.021 mm at the rigid level) has no budget: one line, exit 2."""
    scene = tmp_path / "u.toml"
    scene.write_text(text)
    spec = "displacement:z<=0.06mm@q50"
    assert main(["budget", str(scene), "--model", "quasi-static", "--spec", spec, "-n", "64",
                 "-o", str(tmp_path / "b"), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "measured sweep" in printed
    passes, fails = (float(w.rstrip(",")) for w in printed.split("limiting: scale ")[1].split()[0:3:2])
    assert passes < 1 and fails / passes <= 1.05 + 1e-9
    assert main(["budget", str(scene), "--model", "quasi-static", "--spec", "displacement:z<=0.01mm@q50",
                 "-n", "64", "-o", str(tmp_path / "c"), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "still fails at clearance scale" in err and "geometric error" in err


def test_until_grows_an_ensemble_of_realised_robots_with_the_same_draws(text, tmp_path):
    """--until adds realisations to a scene with [uncertain.*] inputs; each row holds the inputs a
    plain run of that realisation draws."""
    scene = tmp_path / "u.toml"
    scene.write_text(text)
    out = tmp_path / "until.nc"
    assert main(["run", str(scene), "--model", "quasi-static", "--until", "displacement:z@q50<=20%", "-n", "64",
                 "--workers", "1", "-o", str(out)]) in (0, 3)
    ds = load_netcdf(out)
    n = ds.sizes["realization"]
    assert n > 6
    plain = run_chunk(_spec(text), [n - 1])
    assert np.array_equal(ds["uncertain_input"].values[-1], plain["uncertain_input"].values[0])


def test_studies_refuse_what_they_cannot_answer(text, tmp_path, capsys):
    """A budget cannot scale drawn clearance sizes, Sobol' indices need independent inputs: one line, exit 2."""
    scene = tmp_path / "u.toml"
    scene.write_text(text + '[uncertain.c]\nparameter = "clearance.spherical_C_m"\nlaw = "normal"\nstd_m = 1e-6\n')
    assert main(["budget", str(scene), "--model", "quasi-static", "--spec", "displacement:z<=1mm@q50",
                 "-n", "64", "-o", str(tmp_path / "b"), "--workers", "1"]) == 2
    assert "[uncertain.c] draws clearance sizes about the [clearance] values" in capsys.readouterr().err
    rod = TABLES.split("[uncertain.zero]")[0].replace("crank]", "rod]").replace("crank_length", "rod_length")
    scene.write_text(text + rod + '[correlation.c]\ninputs = ["crank", "rod"]\nmatrix = [[1, 0.5], [0.5, 1]]\n')
    assert main(["sensitivity", str(scene), "--model", "quasi-static", "-n", "64", "-o", str(tmp_path / "s.nc"),
                 "--workers", "1"]) == 2
    assert "[correlation.c]: Sobol' indices need independent inputs" in capsys.readouterr().err
    assert not (tmp_path / "s.nc").exists() and not (tmp_path / "b").exists()


def test_a_single_run_file_records_its_inputs(text, tmp_path, capsys):
    scene = tmp_path / "u.toml"
    scene.write_text(text)
    path = tmp_path / "r.nc"
    assert main(["simulate", str(scene), "--model", "rigid", "--seed", "3", "--realization", "2", "-o", str(path)]) == 0
    ds = load_netcdf(path)
    from rss6core.uncertain import draw_inputs
    assert np.array_equal(ds["uncertain_input"].values, draw_inputs(parse_scene(text), 3, 2).values)
    assert ds["input_units"].values[0] == "m" and cf_errors(path) == []
    assert float(ds["max_abs_error"].sel(window="whole", quantity="displacement", direction="z")) > 1e-7


def test_the_shipped_manufacturing_scene_draws_its_tolerances():
    from pipeline.scenes.catalogue import find_scene
    from rss6core import simulate
    scene = find_scene("paper_manufacturing")
    assert [i.name for i in scene.uncertain.inputs] == [
        "crank_length", "rod_length", "base_radius", "platform_radius", "base_angle", "platform_angle",
        "actuator_zero", "youngs_modulus", "friction", "payload_mass", "payload_inertia"]
    assert scene.uncertain.dimension == 6 * 7 + 1 + 18 + 2
    assert scene.tolerance.revolute_radial is not None and scene.simulation.model == "quasi-static"
    rigid = simulate(scene, "rigid", seed=0, realization=0)
    assert rigid.status == "finished" and 1e-5 < np.abs(rigid.displacement[:, :3]).max() < 2e-3
