"""Clearance-size tolerance bands: the scene keys, the drawn law, reproducibility, the file variable."""
import numpy as np
import pytest
from scipy.stats import truncnorm

from rss6core.clearance import clearances_from_uniforms, draw_clearances
from rss6core.scene import SceneError, parse_scene

DRAWS = 2000   # realisations x 6 joints = 12000 sizes per family


@pytest.fixture(scope="module")
def tolerance(configs):
    return parse_scene((configs / "paper_tolerance.toml").read_text())


def _sizes(scene, seed=0):
    draws = [draw_clearances(scene, seed, r) for r in range(DRAWS)]
    return {f: np.concatenate([getattr(d, f) for d in draws]) for f in ("radial_size", "axial_size", "size_C")}


def test_sizes_follow_each_familys_band(tolerance):
    s, n = _sizes(tolerance), 6 * DRAWS
    band = tolerance.tolerance.revolute_radial   # truncated normal about the nominal size
    a, b = (band.low - 0.25e-3) / band.std, (band.high - 0.25e-3) / band.std
    law = truncnorm(a, b, loc=0.25e-3, scale=band.std)
    assert band.low <= s["radial_size"].min() and s["radial_size"].max() <= band.high
    assert abs(s["radial_size"].mean() - law.mean()) < 4 * law.std() / np.sqrt(n)       # 4 sigma
    assert abs(s["radial_size"].std() / law.std() - 1) < 4 * np.sqrt(0.5 / n) * 1.2    # 4 sigma, kurtosis margin
    for key, fam in (("axial_size", "revolute_axial"), ("size_C", "spherical_C")):   # uniform
        lo, hi = getattr(tolerance.tolerance, fam).low, getattr(tolerance.tolerance, fam).high
        x = (s[key] - lo) / (hi - lo)
        assert 0 <= x.min() and x.max() <= 1
        assert abs(x.mean() - 0.5) < 4 * np.sqrt(1 / 12 / n)
        assert abs(x.std() - np.sqrt(1 / 12)) < 4 * 0.13 / np.sqrt(n)   # 4 sigma: sd(s) = 0.129 / sqrt(n)


def test_sizes_are_reproducible_and_the_uniforms_path_draws_them(tolerance):
    d1, d2 = draw_clearances(tolerance, 7, 3), draw_clearances(tolerance, 7, 3)
    assert np.array_equal(d1.radial_size, d2.radial_size) and np.array_equal(d1.size_B, d2.size_B)
    assert not np.array_equal(d1.size_B, draw_clearances(tolerance, 7, 4).size_B)
    u = np.linspace(0.01, 0.99, 24 + 54)
    q = clearances_from_uniforms(tolerance, u)
    band = tolerance.tolerance.spherical_C
    assert np.allclose(q.size_C, band.low + (band.high - band.low) * u[12:18])


def test_no_tolerance_scene_draws_exactly_as_before(paper, paper_text):
    # the same text with an empty band section draws nothing differently, and sizes stay nominal
    same = parse_scene(paper_text + "\n[tolerance]\n")
    for r in range(3):
        a, b = draw_clearances(paper, 1, r), draw_clearances(same, 1, r)
        assert np.array_equal(a.e_A, b.e_A) and np.array_equal(a.e_B, b.e_B)
        assert np.all(a.radial_size == paper.clearance.revolute_radial)
    # values of main 7dc33bd (before tolerance bands) for seed 1, realisation 2: the stream is unchanged
    d = draw_clearances(paper, 1, 2)
    assert np.allclose(d.e_B[3], [2.19816164e-05, -4.51617088e-06, 5.08189270e-05], rtol=1e-8, atol=0)
    assert np.allclose(d.e_A[5], [-1.73142626e-04, 1.21658205e-04, 9.56477458e-05], rtol=1e-8, atol=0)


@pytest.mark.parametrize("band, message", [
    ('law = "normal"\nlow_m = 1e-4\nhigh_m = 3e-4', "[tolerance.spherical_B] std_m"),
    ('law = "uniform"\nlow_m = 3e-4\nhigh_m = 1e-4', "[tolerance.spherical_B] low_m"),
    ('law = "normal"\nlow_m = 3e-4\nhigh_m = 4e-4\nstd_m = 1e-5', "[tolerance.spherical_B] low_m, high_m"),
    ('law = "gauss"\nlow_m = 1e-4\nhigh_m = 3e-4', "[tolerance.spherical_B] law"),
    ('law = "uniform"\nlow_m = 1e-4\nhigh = 3e-4', "[tolerance.spherical_B] high"),
    ('law = "uniform"\nlow_m = 1e-4\nhigh_m = 0.35', "[tolerance.spherical_B] high_m: 0.35 m is not below "
                                                    "[contact] sphere_radius_m"),
])
def test_bad_bands_are_one_line_errors_naming_the_key(paper_text, band, message):
    with pytest.raises(SceneError) as err:
        parse_scene(paper_text + "\n[tolerance.spherical_B]\n" + band + "\n")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_ensemble_file_records_each_realisations_drawn_sizes(tmp_path, configs):
    from pipeline.ensemble.run import EnsembleSpec, run_ensemble
    from pipeline.scenes.catalogue import scene_text
    from pipeline.files.opening import open_ensemble
    text = scene_text("smoke") + ('\n[tolerance.spherical_C]\nlaw = "uniform"\nlow_m = 1e-4\nhigh_m = 3e-4\n')
    spec = EnsembleSpec(text, "smoke", "quasi-static", "newmark", 1e-3, 4, 5, "summary")
    run_ensemble(spec, 4, tmp_path / "t.nc", workers=1, chunk=3, progress=False)
    with open_ensemble(tmp_path / "t.nc") as ds:
        size = ds["clearance_size"]
        assert size.dims == ("realization", "joint") and size.attrs["units"] == "m"
        scene = parse_scene(text)
        want = np.stack([draw_clearances(scene, 5, r).size_C for r in range(4)])
        assert np.array_equal(size.sel(joint=[f"C{k}" for k in range(1, 7)]).values, want)
        assert np.all((1e-4 <= want) & (want <= 3e-4)) and np.ptp(want) > 0
