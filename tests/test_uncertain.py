"""Uncertain scene inputs: the [uncertain.NAME] tables' refusals, the laws' draws and their streams."""
import numpy as np
import pytest
from scipy import stats

from rss6core import SceneError, parse_scene
from rss6core.clearance import realization_rng
from rss6core.levels import MODEL_LEVELS, check_uncertain_level
from rss6core.uncertain import TAIL, draw_inputs, input_rng, inputs_from_uniforms
from pipeline.scenes.variant import scene_variant


def _with(text: str, tables: str):
    return parse_scene(text + "\n" + tables, "s.toml")


LENGTHS = """
[uncertain.crank]
parameter = "geometry.crank_length_m"
each = "leg"
law = "uniform"
low_m = -0.1e-3
high_m = 0.1e-3
"""


def test_reaction_eccentricities_with_uncertain_inputs_are_refused_only_where_they_are_read(paper_text):
    """quasi_static_eccentricity = "reaction" is read by the quasi-static level alone, which cannot yet take
    it with [uncertain.*] inputs: refused there in one line naming the key; every other level takes the scene
    (the paper and contact levels were refused too, for a key they never read)."""
    text = scene_variant(paper_text, {"simulation": {"quasi_static_eccentricity": "reaction"}}, add=True)
    scene = _with(text, LENGTHS)
    with pytest.raises(ValueError, match='quasi_static_eccentricity = "drawn"'):
        check_uncertain_level(scene, "quasi-static")
    for model in set(MODEL_LEVELS) - {"quasi-static"}:
        check_uncertain_level(scene, model)


def test_a_table_is_read_with_its_law_and_draw_count(paper_text):
    scene = _with(paper_text, LENGTHS)
    (item,) = scene.uncertain.inputs
    assert (item.name, item.parameter, item.each, item.count, item.law) == (
        "crank", "geometry.crank_length_m", "leg", 6, "uniform")
    assert dict(item.parameters) == {"low": -0.1e-3, "high": 0.1e-3}
    assert item.law_text() == "uniform deviation (low_m=-0.0001, high_m=0.0001)"
    assert scene.uncertain.dimension == 6


@pytest.mark.parametrize("table, message", [
    ('parameter = "geometry.crank_lenght_m"\nlaw = "uniform"\nlow_m = -1e-4\nhigh_m = 1e-4',
     r"\[uncertain.x\] parameter: 'geometry.crank_lenght_m' is not a scene key .*crank_length_m"),
    ('parameter = "geometry.crank_length_m"\nlaw = "uniform"\nlow_mm = -0.1\nhigh_m = 1e-4',
     r"\[uncertain.x\] low_mm: law parameters are in the key's unit, m: write low_m"),
    ('parameter = "geometry.base_angles_deg"\nlaw = "normal"\nstd_m = 0.1',
     r"\[uncertain.x\] std_m: .* write std_deg"),
    ('parameter = "material.youngs_modulus_Pa"\nlaw = "lognormal"\nsigma_Pa = 0.05',
     r"\[uncertain.x\] sigma_Pa: law parameters are a factor, dimensionless: write sigma"),
    ('parameter = "geometry.crank_length_m"\nlaw = "uniform"\nlow_m = -1e-4',
     r"\[uncertain.x\] high_m: missing"),
    ('parameter = "geometry.crank_length_m"\nlaw = "uniform"\nlow_m = -1e-4\nhigh_m = 1e-4\nwidth_m = 1',
     r"\[uncertain.x\] width_m: not a parameter of law 'uniform'"),
    ('parameter = "geometry.crank_length_m"\nlaw = "uniform"\nlow_m = 1e-4\nhigh_m = 1e-4',
     r"\[uncertain.x\] low_m: must be smaller than high_m"),
    ('parameter = "geometry.crank_length_m"\nlaw = "triangular"\nlow_m = -1e-4\nmode_m = 2e-4\nhigh_m = 1e-4',
     r"\[uncertain.x\] mode_m: must lie in \[low_m, high_m\]"),
    ('parameter = "geometry.crank_length_m"\nlaw = "gamma"\nlow_m = -1e-4',
     r"\[uncertain.x\] law: 'gamma' is not one of normal, truncated-normal"),
    ('parameter = "geometry.crank_length_m"\neach = "link"\nlaw = "uniform"\nlow_m = -1e-4\nhigh_m = 1e-4',
     r"\[uncertain.x\] each: 'link' is not one of one, leg for geometry.crank_length_m"),
    ('parameter = "geometry.crank_length_m"\nlaw = "uniform"\nlow_m = -0.3\nhigh_m = 1e-4',
     r"\[uncertain.x\] geometry.crank_length_m: law 'uniform' can draw .* must be positive"),
    ('parameter = "geometry.rod_length_m"\nlaw = "normal"\nstd_m = 0.1',   # 1e-9 quantile: -6 std
     r"\[uncertain.x\] geometry.rod_length_m: law 'normal' can draw .*quantiles.* must be positive"),
    ('parameter = "material.youngs_modulus_Pa"\nlaw = "normal"\nstd_Pa = 20e9',
     r"\[uncertain.x\] material.youngs_modulus_Pa: law 'normal' can draw"),
    ('parameter = "material.youngs_modulus_Pa"\nlaw = "lognormal"\nsigma = 0.6',   # 70 GPa exp(+-6 x 0.6)
     r"\[uncertain.x\] material.youngs_modulus_Pa: law 'lognormal' can draw values in \[1.9\d+e\+09, 2.5\d+e\+12\] Pa, "
     r"outside \[1e\+08, 2e\+12\], beyond any 6-RSS robot's links \(a modulus in GPa or MPa"),
    ('parameter = "material.density_kg_m3"\nlaw = "uniform"\nlow_kg_m3 = -2650\nhigh_kg_m3 = 0',   # 2.7 g/cm^3 - 2.65
     r"\[uncertain.x\] material.density_kg_m3: law 'uniform' can draw values in \[50, 2700\] kg m-3, "
     r"outside \[100, 25000\]"),
    ('parameter = "platform.mass_kg"\nlaw = "uniform"\nlow_kg = -2\nhigh_kg = 1',
     r"\[uncertain.x\] platform.mass_kg: .* must be positive"),
    ('parameter = "contact.friction_coefficient"\nlaw = "uniform"\nlow = -0.2\nhigh = 0.1',
     r"\[uncertain.x\] contact.friction_coefficient: .* must be non-negative"),
    ('parameter = "contact.restitution"\nlaw = "uniform"\nlow = -0.05\nhigh = 0.15',
     r"\[uncertain.x\] contact.restitution: .*\[0.85, 1.05\] 1 .* must be in \(0, 1\]"),
    ('parameter = "contact.restitution"\nlaw = "lognormal"\nsigma = 0.05',   # 0.9 exp(6 x 0.05) > 1
     r"\[uncertain.x\] contact.restitution: law 'lognormal' can draw"),
    ('parameter = "geometry.actuator_offsets_deg"\nlaw = "lognormal"\nsigma = 0.01',
     r"\[uncertain.x\] law: 'lognormal' is a factor on a positive value"),
    ('parameter = "geometry.crank_length_m"\nlaw = "truncated-normal"\nstd_m = 0\nlow_m = -1e-4\nhigh_m = 1e-4',
     r"\[uncertain.x\] std_m: must be positive"),
    ('parameter = "clearance.revolute_radial_m"\neach = "joint"\nlaw = "uniform"\nlow_m = -0.3e-3\nhigh_m = 0',
     r"\[uncertain.x\] clearance.revolute_radial_m: law 'uniform' can draw .*-5e-05.* must be non-negative"),
    ('parameter = "clearance.spherical_C_m"\nlaw = "uniform"\nlow_m = 0\nhigh_m = 0.00975',   # 0.25 + 9.75 mm
     r"\[uncertain.x\] clearance.spherical_C_m: law 'uniform' can draw sizes up to 0.01 m, not below \[contact\] "
     r"sphere_radius_m = 0.01 m"),
    ('parameter = "clearance.spherical_B_m"\neach = "leg"\nlaw = "uniform"\nlow_m = 0\nhigh_m = 1e-5',
     r"\[uncertain.x\] each: 'leg' is not one of one, joint for clearance.spherical_B_m"),
])
def test_a_bad_table_is_refused_in_one_line_naming_table_and_key(paper_text, table, message):
    with pytest.raises(SceneError, match=message) as info:
        _with(paper_text, "[uncertain.x]\n" + table)
    assert str(info.value).startswith("s.toml: ") and "\n" not in str(info.value)


def test_a_clearance_size_drawn_by_a_band_too_is_refused(paper_text, configs):
    """[tolerance.<family>] bands and [sampling] size_tolerance are the older form of the same draw: a
    family takes one of them or an [uncertain] table, in one line naming both."""
    table = ('[uncertain.x]\nparameter = "clearance.revolute_radial_m"\neach = "joint"\nlaw = "uniform"\n'
             'low_m = -1e-5\nhigh_m = 1e-5')
    with pytest.raises(SceneError, match=r"^s.toml: \[uncertain.x\] parameter: clearance.revolute_radial_m is "
                                         r"drawn by \[tolerance.revolute_radial\] already; give one of them$"):
        _with((configs / "paper_tolerance.toml").read_text(), table)
    with pytest.raises(SceneError, match=r"is drawn by \[sampling\] size_tolerance already"):
        _with(paper_text.replace("size_tolerance = 0.0 ", "size_tolerance = 0.1 ", 1), table)


def test_a_key_drawn_twice_and_bad_correlations_are_refused(paper_text):
    twice = LENGTHS + LENGTHS.replace("uncertain.crank", "uncertain.again")
    with pytest.raises(SceneError, match=r"\[uncertain.again\] parameter: .* already drawn by \[uncertain.crank\]"):
        _with(paper_text, twice)
    rod = LENGTHS.replace("crank]", "rod]").replace("crank_length", "rod_length")
    for matrix, message in [("[[1, 0.5], [0.4, 1]]", "symmetric"), ("[[1, 2], [2, 1]]", "positive definite"),
                            ("[[1, 0.5]]", "2 rows of 2")]:
        with pytest.raises(SceneError, match=rf"\[correlation.c\] matrix: .*{message}"):
            _with(paper_text, LENGTHS + rod + f'[correlation.c]\ninputs = ["crank", "rod"]\nmatrix = {matrix}\n')
    with pytest.raises(SceneError, match=r"\[correlation.c\] inputs: 'nope' is no \[uncertain.nope\]"):
        _with(paper_text, LENGTHS + '[correlation.c]\ninputs = ["crank", "nope"]\nmatrix = [[1, 0], [0, 1]]\n')


def test_nominal_actuator_offsets_are_zero(paper_text):
    text = paper_text.replace("rod_length_m = 0.500", "rod_length_m = 0.500\nactuator_offsets_deg = [1, 0, 0, 0, 0, 0]")
    with pytest.raises(SceneError, match=r"\[geometry\] actuator_offsets_deg: the nominal offsets are 0"):
        parse_scene(text)


# --- the laws' draws ---------------------------------------------------------

LAW_TABLES = {   # law table on the crank length, and the scipy law of its deviation (m) or factor
    "normal": ("std_m = 2e-4\nmean_m = 1e-4", stats.norm(1e-4, 2e-4)),
    "truncated-normal": ("std_m = 2e-4\nlow_m = -1e-4\nhigh_m = 3e-4", stats.truncnorm(-0.5, 1.5, 0, 2e-4)),
    "lognormal": ("sigma = 0.02\nmedian = 1.01", stats.lognorm(0.02, scale=1.01)),
    "uniform": ("low_m = -1e-4\nhigh_m = 3e-4", stats.uniform(-1e-4, 4e-4)),
    "triangular": ("low_m = -1e-4\nmode_m = 0\nhigh_m = 3e-4", stats.triang(0.25, -1e-4, 4e-4)),
}


def _law_scene(paper_text, law, each="leg"):
    return _with(paper_text, f'[uncertain.c]\nparameter = "geometry.crank_length_m"\neach = "{each}"\n'
                             f'law = "{law}"\n' + LAW_TABLES[law][0])


@pytest.mark.parametrize("law", list(LAW_TABLES))
def test_each_law_draws_its_mean_spread_and_limits(paper_text, law):
    """4000 realisations x 6 legs: mean within 5 standard errors, variance within 5 of its standard
    errors (from the law's fourth moment), every draw inside the law's support (TAIL-cut if unbounded)."""
    scene, ref = _law_scene(paper_text, law), LAW_TABLES[law][1]
    x = np.concatenate([draw_inputs(scene, 7, r).values for r in range(4000)])
    n = x.size
    mean, var, kurt = ref.stats(moments="mvk")
    assert abs(x.mean() - mean) < 5 * np.sqrt(var / n)
    var_se = np.sqrt(var ** 2 * (kurt + 2) / n)
    assert abs(x.var() - var) < 5 * var_se
    lo, hi = ref.ppf([TAIL, 1 - TAIL]) if law in ("normal", "lognormal") else ref.support()
    assert lo <= x.min() and x.max() <= hi
    assert stats.kstest(x, ref.cdf).pvalue > 1e-4


def test_draws_are_a_function_of_uniforms_and_their_own_stream(paper_text):
    scene = _law_scene(paper_text, "normal")
    a, b = draw_inputs(scene, 3, 5), draw_inputs(scene, 3, 5)
    assert np.array_equal(a.values, b.values)
    u = input_rng(3, 5).uniform(size=6)
    assert np.array_equal(inputs_from_uniforms(scene.uncertain, u).values, a.values)
    # never the clearance stream SeedSequence([seed, r])
    assert not np.any(np.isin(u, realization_rng(3, 5).uniform(size=1000)))
    assert not np.array_equal(draw_inputs(scene, 3, 6).values, a.values)
    given = draw_inputs(scene, 3, 5, uniforms=lambda r, d: np.linspace(0.1, 0.9, d), offset=4)
    assert np.array_equal(given.values, inputs_from_uniforms(scene.uncertain, np.linspace(0.1, 0.9, 10)[4:]).values)


def test_realised_values_follow_each(paper_text):
    scene = _with(paper_text, LENGTHS + '[uncertain.ang]\nparameter = "geometry.base_angles_deg"\n'
                              'law = "uniform"\nlow_deg = 1\nhigh_deg = 2\n'
                              '[uncertain.e]\nparameter = "material.youngs_modulus_Pa"\neach = "link"\n'
                              'law = "lognormal"\nsigma = 0.05\n')
    d = draw_inputs(scene, 0, 0)
    assert d.values.shape == (6 + 1 + 12,)
    assert np.array_equal(d.realised("geometry.crank_length_m"), 0.216 + d.of("crank"))
    angles = d.realised("geometry.base_angles_deg")   # one shared deviation, in rad
    assert angles == pytest.approx(scene.geometry.base_angles + d.of("ang")[0], abs=1e-15)
    assert np.radians(1) <= d.of("ang")[0] <= np.radians(2)
    assert np.array_equal(d.realised("material.youngs_modulus_Pa"), 70e9 * d.of("e"))
    assert d.realised("platform.mass_kg") is None


def test_a_gaussian_copula_correlates_inputs_draw_by_draw(paper_text):
    rod = LENGTHS.replace("crank]", "rod]").replace("crank_length", "rod_length")
    scene = _with(paper_text, LENGTHS + rod + '[correlation.c]\ninputs = ["crank", "rod"]\n'
                                             'matrix = [[1, 0.8], [0.8, 1]]\n')
    d = np.array([draw_inputs(scene, 1, r).values for r in range(3000)])
    z = stats.norm.ppf((d + 1e-4) / 2e-4)      # back to the normal scores of the two uniform laws
    rho = np.corrcoef(z[:, :6].ravel(), z[:, 6:].ravel())[0, 1]
    assert rho == pytest.approx(0.8, abs=5 * (1 - 0.8 ** 2) / np.sqrt(z[:, :6].size))
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 5 / np.sqrt(3000)   # legs stay independent
