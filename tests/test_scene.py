"""Scene loading: the reference values, and one named error per kind of bad input."""
import re
import subprocess
import sys

import numpy as np
import pytest

from rss6core import SceneError, parse_scene
from pipeline.scenes.catalogue import find_scene, scene_names
from rss6core import load_scene


def _edit(text, old, new):
    assert old in text, f"fixture text lacks {old!r}"
    return text.replace(old, new, 1)


def test_paper_values_in_si(paper):
    assert paper.geometry.base_radius == pytest.approx(0.14527)
    assert np.degrees(paper.geometry.platform_angles) == pytest.approx([-80, 80, 40, 200, 160, 320])
    assert paper.trajectory.amplitude == pytest.approx([0, 0.05, 0.08, np.radians(20), np.radians(20), 0])
    assert paper.times[-1] == pytest.approx(2.0) and len(paper.times) == 2001
    assert paper.material.poisson_ratio == pytest.approx(70 / 53 - 1)


def test_shipped_scenes_are_found_by_name():
    assert {"paper", "paper_050", "smoke"} <= set(scene_names())
    assert find_scene("paper_050").clearance.spherical_B == pytest.approx(0.5e-3)
    with pytest.raises(SceneError, match=r"^papr: no such scene file or shipped scene "
                                         r"\(shipped scenes: paper, paper_050, "):
        find_scene("papr")


def test_the_core_reads_files_only_and_never_imports_the_pipeline(tmp_path):
    """load_scene takes a path, wherever it runs; the shipped-scene names live in pipeline."""
    code = ("import sys, rss6core, rss6core.models\n"
            "try:\n    rss6core.load_scene('nope.toml')\n"
            "except rss6core.SceneError as exc:\n    print(exc)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pipeline'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, check=True).stdout.splitlines()
    assert out == ["nope.toml: no such scene file", "[]"]


def test_scene_is_immutable(paper):
    with pytest.raises(AttributeError):
        paper.time_step = 1.0
    with pytest.raises(ValueError):
        paper.geometry.base_angles[0] = 0.0


def test_unknown_key_is_named_with_a_suggestion(paper_text):
    with pytest.raises(SceneError, match=r"unknown key \[geometry\] crank_lenght_m.*crank_length_m"):
        parse_scene(_edit(paper_text, "crank_length_m", "crank_lenght_m"))


def test_missing_key_is_named(paper_text):
    with pytest.raises(SceneError, match=r"missing key \[platform\] mass_kg"):
        parse_scene(_edit(paper_text, "mass_kg = 1.366\n", ""))


def test_wrong_type_is_named(paper_text):
    with pytest.raises(SceneError, match=r"\[geometry\] rod_length_m: expected a number"):
        parse_scene(_edit(paper_text, "rod_length_m = 0.500", 'rod_length_m = "0.5"'))


def test_wrong_array_length_is_named(paper_text):
    with pytest.raises(SceneError, match=r"\[geometry\] base_angles_deg: expected a list of 6"):
        parse_scene(_edit(paper_text, "[-15.0, 15.0,", "[15.0,"))


def test_negative_length_is_rejected(paper_text):
    with pytest.raises(SceneError, match=r"\[geometry\] crank_length_m: must be positive"):
        parse_scene(_edit(paper_text, "crank_length_m = 0.216", "crank_length_m = -0.216"))


def test_negative_clearance_is_rejected(paper_text):
    with pytest.raises(SceneError, match=r"\[clearance\] spherical_C_m: must be non-negative"):
        parse_scene(_edit(paper_text, "spherical_C_m = 0.25e-3", "spherical_C_m = -0.25e-3"))


def test_zero_mass_is_rejected(paper_text):
    with pytest.raises(SceneError, match=r"\[platform\] mass_kg: must be positive, got 0"):
        parse_scene(_edit(paper_text, "mass_kg = 1.366", "mass_kg = 0.0"))


def test_unreachable_trajectory_names_leg_and_time(paper_text):
    # 200 mm vertical amplitude lifts the platform out of reach of the legs
    text = _edit(paper_text, "[0.0, 0.050, 0.080]", "[0.0, 0.050, 0.200]")
    with pytest.raises(SceneError, match=r"workspace: leg \d cannot reach .* at t = \d+\.\d+ s") as e:
        parse_scene(text)
    leg, t = map(float, re.search(r"leg (\d) .* t = ([\d.]+) s", str(e.value)).groups())
    assert 1 <= leg <= 6 and 0 < t < 0.5  # first excursion is in the first quarter period


def test_time_step_must_divide_duration(paper_text):
    said = r"\[simulation\] time_step_s: time step 0.003 s does not divide the duration 2.0 s"
    with pytest.raises(SceneError, match=said):
        parse_scene(_edit(paper_text, "time_step_s = 1.0e-3", "time_step_s = 3.0e-3"))


@pytest.mark.parametrize("step, steps", [("0.25", 8), ("1.0e9", 0), ("1.0e-6", 2_000_000),
                                         ("1.0e-12", 2_000_000_000_000)])
def test_a_run_takes_ten_to_a_million_steps(paper_text, step, steps):
    """A step that divides the 2 s duration into too few steps for the run's windows and derivatives, or
    into so many that its arrays would not fit, is refused by name before any work (bad-input audit:
    0 steps had passed and then failed in the run)."""
    with pytest.raises(SceneError, match=rf"\[simulation\] time_step_s: .* gives {steps} steps .* 10 to 1000000"):
        parse_scene(_edit(paper_text, "time_step_s = 1.0e-3", f"time_step_s = {step}"))
    parse_scene(_edit(paper_text, "time_step_s = 1.0e-3", "time_step_s = 0.2"))   # 10 steps: the least


def test_a_step_count_too_large_to_read_is_rounded_in_its_message(paper_text):
    """1e-300 s gave a 301-digit step count in the one-line error."""
    with pytest.raises(SceneError, match=r"gives about 2e\+300 steps over the duration 2.0 s") as err:
        parse_scene(_edit(paper_text, "time_step_s = 1.0e-3", "time_step_s = 1.0e-300"))
    assert len(str(err.value)) < 200


def test_tube_inner_diameter_below_outer(paper_text):
    with pytest.raises(SceneError, match=r"\[rod_section\] inner_diameter_m"):
        parse_scene(_edit(paper_text, "inner_diameter_m = 0.010", "inner_diameter_m = 0.030"))


def test_not_toml_is_named():
    with pytest.raises(SceneError, match=r"bad.toml: not valid TOML"):
        parse_scene("name = ", "bad.toml")


def test_missing_file_is_named(tmp_path):
    with pytest.raises(SceneError, match=r"nope.toml: no such scene file"):
        load_scene(tmp_path / "nope.toml")


@pytest.mark.parametrize("line, said", [
    ("elements_per_link = true", "[simulation] elements_per_link: expected a number, got true (a boolean)"),
    ('elements_per_link = "4"', '[simulation] elements_per_link: expected a number, got "4" (a string)'),
    ("elements_per_link = 4.5", "[simulation] elements_per_link: expected an integer, got 4.5")])
def test_a_value_of_the_wrong_kind_is_quoted_as_toml_spells_it(paper_text, line, said):
    with pytest.raises(SceneError, match=re.escape(said) + "$"):
        parse_scene(_edit(paper_text, "elements_per_link = 4", line))


def test_a_binary_file_given_as_a_scene_is_named_as_such(tmp_path):
    """An ensemble file passed as CONFIG: what it is, not a codec error."""
    (tmp_path / "e.nc").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(128, 256)))
    with pytest.raises(SceneError, match=r"e.nc: not a scene file but binary \(a netCDF file: an rss6 output\?\); "
                                         "a CONFIG is a scene TOML file"):
        load_scene(tmp_path / "e.nc")
    (tmp_path / "b.toml").write_bytes(bytes(range(128, 256)))
    with pytest.raises(SceneError, match=r"b.toml: not a scene file but binary; a CONFIG"):
        load_scene(tmp_path / "b.toml")


def test_contact_time_step_must_divide_the_time_step(paper_text):
    text = _edit(paper_text, "contact_time_step_s = 2.0e-4", "contact_time_step_s = 3.0e-4")
    with pytest.raises(SceneError, match=r"\[simulation\] contact_time_step_s"):
        parse_scene(text)
    fine = parse_scene(_edit(paper_text, "contact_time_step_s = 2.0e-4", "contact_time_step_s = 2.5e-4"))
    assert fine.simulation.contact_time_step == pytest.approx(2.5e-4)
    assert fine.contact.impact_speed_floor == pytest.approx(1e-3)


@pytest.mark.parametrize("old, new, key, radius", [
    ("revolute_radial_m = 0.25e-3", "revolute_radial_m = 0.25", "revolute_radial_m", "journal_radius_m"),
    ("spherical_B_m = 0.25e-3", "spherical_B_m = 0.010", "spherical_B_m", "sphere_radius_m"),
])
def test_a_clearance_not_below_its_joints_radius_is_refused(paper_text, old, new, key, radius):
    """A value in mm typed into an _m key (250 mm on a 10 mm pin), or a gap as wide as the ball."""
    with pytest.raises(SceneError, match=rf"\[clearance\] {key}: .* not below \[contact\] {radius}"):
        parse_scene(_edit(paper_text, old, new))
    assert parse_scene(_edit(paper_text, old, new.replace("0.25", "0.0099").replace("0.010", "0.0099")))


def test_a_relative_size_tolerance_whose_largest_draw_reaches_the_radius_is_refused(paper_text):
    """[sampling] size_tolerance draws sizes up to twice the nominal: 6 mm nominal on a 10 mm pin
    passes the nominal check but not that bound; 4.9 mm passes both."""
    text = _edit(paper_text, "size_tolerance = 0.0 ", "size_tolerance = 0.1 ")
    with pytest.raises(SceneError, match=r"\[sampling\] size_tolerance: .* 2 x \[clearance\] revolute_radial_m "
                                         r"\(0\.006 m\) = 0\.012 m, not below \[contact\] journal_radius_m = 0\.01 m"):
        parse_scene(_edit(text, "revolute_radial_m = 0.25e-3", "revolute_radial_m = 6.0e-3"))
    assert parse_scene(_edit(text, "revolute_radial_m = 0.25e-3", "revolute_radial_m = 4.9e-3"))
    assert parse_scene(_edit(paper_text, "revolute_radial_m = 0.25e-3", "revolute_radial_m = 6.0e-3"))


def test_new_models_are_accepted_and_a_typo_is_named(paper_text):
    for model in ("paper", "contact"):
        scene = parse_scene(_edit(paper_text, 'model = "elastic"', f'model = "{model}"'))
        assert scene.simulation.model == model
    with pytest.raises(SceneError, match=r"\[simulation\] model.*'contakt'"):
        parse_scene(_edit(paper_text, 'model = "elastic"', 'model = "contakt"'))


def test_contact_stiffness_scale_defaults_to_one_and_must_be_positive(paper_text):
    assert parse_scene(paper_text).contact.stiffness_scale == 1.0
    line = next(ln for ln in paper_text.splitlines() if ln.startswith("slip_velocity_m_s"))
    scaled = parse_scene(_edit(paper_text, line, line + "\nstiffness_scale = 10.0"))
    assert scaled.contact.stiffness_scale == 10.0
    with pytest.raises(SceneError, match=r"\[contact\] stiffness_scale"):
        parse_scene(_edit(paper_text, line, line + "\nstiffness_scale = -1.0"))


def test_adaptive_contact_step_keys_are_read_and_checked(paper_text):
    sim = parse_scene(paper_text).simulation
    assert (sim.contact_time_step, sim.contact_refinements, sim.contact_tolerance) == (2e-4, 4, 1e-8)
    with pytest.raises(SceneError, match=r"\[simulation\] contact_tolerance_m"):
        parse_scene(_edit(paper_text, "contact_tolerance_m = 1.0e-8", "contact_tolerance_m = -1.0e-8"))
    with pytest.raises(SceneError, match=r"\[simulation\] contact_refinements"):
        parse_scene(_edit(paper_text, "contact_refinements = 4", "contact_refinements = 11"))
    with pytest.raises(SceneError, match=r"\[simulation\] contact_refinements"):
        parse_scene(_edit(paper_text, "contact_refinements = 4", "contact_refinements = 2.5"))


def test_settle_time_must_be_shorter_than_the_trajectory(paper_text):
    assert parse_scene(paper_text).simulation.settle_time == 0.0
    with pytest.raises(SceneError, match=r"\[simulation\] settle_time_s"):
        parse_scene(_edit(paper_text, "time_step_s = 1.0e-3", "time_step_s = 1.0e-3\nsettle_time_s = 5.0"))


def test_a_geometry_length_in_mm_written_in_metres_is_named(paper_text):
    """rod_length_m = 450 (mm meant): named with the hint instead of a workspace failure; 20 m passes this
    check (and fails the paper trajectory's workspace instead, not by this message)."""
    line = next(ln for ln in paper_text.splitlines() if ln.startswith("rod_length_m"))
    with pytest.raises(SceneError, match=r"\[geometry\] rod_length_m: 450.0 m is above 20 m, .*in mm written"):
        parse_scene(_edit(paper_text, line, "rod_length_m = 450.0"))
    with pytest.raises(SceneError) as info:
        parse_scene(_edit(paper_text, line, "rod_length_m = 20.0"))
    assert "in mm written" not in str(info.value)


@pytest.mark.parametrize("key, nominal, slip, words", [
    ("youngs_modulus_Pa", "70.0e9", "70.0", "modulus in GPa or MPa"),
    ("density_kg_m3", "2700.0", "2.7", "g/cm^3"),
    ("shear_modulus_Pa", "26.5e9", "26.5", "modulus in GPa or MPa"),
    ("gravity_m_s2", "9.81", "9810.0", "mm/s^2")])
def test_a_material_or_gravity_beyond_any_robot_is_a_unit_slip(paper_text, key, nominal, slip, words):
    """A modulus of 70 Pa or a density of 2.7 kg/m^3 (the helper review's cases: the run diverged at step 1)
    is refused naming the key and the slip it suggests; the bounds' own ends are accepted."""
    with pytest.raises(SceneError, match=rf"{key}: {slip} lies outside .*{re.escape(words)}"):
        parse_scene(_edit(paper_text, f"{key} = {nominal}", f"{key} = {slip}"))
    from rss6core.scene import MAGNITUDES
    low, high = next((lo, hi) for _, k, lo, hi, _ in MAGNITUDES if k == key)
    for end in (low, high) if key != "shear_modulus_Pa" else ():   # its ends: the Poisson ratio's check's
        if key == "youngs_modulus_Pa":   # the shear modulus follows, keeping the Poisson ratio
            text = _edit(_edit(paper_text, "shear_modulus_Pa = 26.5e9", f"shear_modulus_Pa = {end / 2.64!r}"),
                         f"{key} = {nominal}", f"{key} = {end!r}")
        else:
            text = _edit(paper_text, f"{key} = {nominal}", f"{key} = {end!r}")
        assert parse_scene(text).source_text == text


@pytest.mark.parametrize("key, value, ok", [("steady_after_s", 1.9995, False), ("steady_after_s", 1.999, True),
                                            ("settle_time_s", 1.9995, False), ("settle_time_s", 1.999, True)])
def test_a_window_of_the_end_sample_alone_is_refused(paper_text, key, value, ok):
    """A reviewer's steady window [1.9995, 2] s on the 1 ms grid held the end sample alone: its maximum was that
    sample (max == mean), an end-sample artefact. A step before the end keeps two samples and is taken."""
    text = _edit(paper_text, "time_step_s = 1.0e-3", f"time_step_s = 1.0e-3\n{key} = {value}")
    if key == "settle_time_s":   # steady_after_s at most settle_time_s: no start-up window
        text = _edit(text, "time_step_s = 1.0e-3", f"time_step_s = 1.0e-3\nsteady_after_s = {value}")
    if ok:
        parse_scene(text)
        return
    with pytest.raises(SceneError, match=rf"\[simulation\] {key}: the .* window .* holds only the end sample"):
        parse_scene(text)


def test_platform_moments_no_body_has_are_refused(paper_text):
    """I1 + I2 >= I3 holds for every mass distribution (a reviewer's [3e-5, 3e-5, 5.42e-3] was taken); the paper's
    near-flat plate (2.73 + 2.73 >= 5.42) passes, and so does a drawn inertia that keeps it. A shared deviation
    added to all three moments lowers I1 + I2 - I3 by itself: from -4e-5 kg m^2 on it leaves every body."""
    nominal = "inertia_kg_m2 = [2.73e-3, 2.73e-3, 5.42e-3]"
    with pytest.raises(SceneError, match=r"\[platform\] inertia_kg_m2: .* no body's: the largest \(0.00542\)"):
        parse_scene(_edit(paper_text, nominal, "inertia_kg_m2 = [3e-5, 3e-5, 5.42e-3]"))
    table = '\n[uncertain.inertia]\nparameter = "platform.inertia_kg_m2"\nlaw = "uniform"\n'
    parse_scene(paper_text + table + "low_kg_m2 = -3.9e-5\nhigh_kg_m2 = 1e-3\n")
    with pytest.raises(SceneError, match=r"\[uncertain.inertia\] platform.inertia_kg_m2: law 'uniform' can draw"):
        parse_scene(paper_text + table + "low_kg_m2 = -4.1e-5\nhigh_kg_m2 = 1e-3\n")
