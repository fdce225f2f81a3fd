"""ISO 286 fits: published clearance limits, a second table (pressfit), and the radial half."""
import pytest

from pipeline.studies.fits import COST_LAW, IT_UM, SHAFT_ES_UM, FitError, fit_limits, parse_fit

# ANSI B4.2-1978 Table 2 (preferred hole basis clearance fits, ISO 286 limits; its Table 1 is the
# preferred sizes), mm:
# (fit, basic size mm): (min, max) diametral clearance
PUBLISHED_MM = {
    ("H11/c11", 20): (0.110, 0.370), ("H9/d9", 20): (0.065, 0.169), ("H8/f7", 20): (0.020, 0.074),
    ("H7/g6", 20): (0.007, 0.041), ("H7/h6", 20): (0.000, 0.034),
    ("H11/c11", 40): (0.120, 0.440),
    ("H11/c11", 50): (0.130, 0.450), ("H9/d9", 50): (0.080, 0.204), ("H8/f7", 50): (0.025, 0.089),
    ("H7/g6", 50): (0.009, 0.050), ("H7/h6", 50): (0.000, 0.041),
}


@pytest.mark.parametrize("key", sorted(PUBLISHED_MM))
def test_published_clearance_limits(key):
    name, size = key
    lim = fit_limits(name, size * 1e-3)
    assert (lim.min_diametral * 1e3, lim.max_diametral * 1e3) == pytest.approx(PUBLISHED_MM[key], abs=1e-9)
    assert (lim.radial_low, lim.radial_high) == pytest.approx((lim.min_diametral / 2, lim.max_diametral / 2))


def test_limits_are_the_tables_micrometres_as_a_scene_file_would_write_them():
    """Whole micrometres give the metres their decimal spelling (the allocated scene's low_m = 2e-05, not
    1.9999999999999998e-05)."""
    for name in ("H8/e8", "H11/c11", "H7/g6"):
        lim = fit_limits(name, 0.020)
        for value in (lim.min_diametral, lim.max_diametral, lim.radial_low, lim.radial_high):
            assert repr(value) == repr(float(f"{value:.6g}")), (name, value)


def test_paper_tolerance_band_is_h11_c11_diametral():
    """configs/paper_tolerance.toml's radial band 0.110-0.370 mm is H11/c11's DIAMETRAL clearance at 18-30 mm."""
    lim = fit_limits("H11/c11", 0.020)
    assert (lim.min_diametral, lim.max_diametral) == pytest.approx((0.110e-3, 0.370e-3))


def test_against_pressfit_tables():
    pressfit = pytest.importorskip("pressfit")
    sizes = [1, 3, 4.5, 6, 8, 10, 14, 18, 24, 30, 35, 40, 45, 50, 60, 65, 70, 80, 90, 100, 110, 120]
    checked = 0
    for hole in IT_UM:
        for letter in SHAFT_ES_UM:
            for grade in IT_UM:
                for size in sizes:
                    name = f"H{hole}/{letter}{grade}"
                    ref = pressfit.fit(name, size).clearance_um
                    lim = fit_limits(name, size * 1e-3)
                    assert (lim.min_diametral * 1e6, lim.max_diametral * 1e6) == pytest.approx(ref, abs=1e-6), \
                        (name, size)
                    checked += 1
    assert checked == 7 * 6 * 7 * len(sizes)


@pytest.mark.parametrize("bad", ["H7g6", "H4/g6", "H7/k6", "G7/h6", "H12/c11"])
def test_bad_fit_names(bad):
    with pytest.raises(FitError, match="fit"):
        parse_fit(bad)


def test_diameter_outside_tables():
    with pytest.raises(FitError, match="120 mm"):
        fit_limits("H7/g6", 0.2)


def test_cost_law_grows_as_the_tolerance_closes():
    costs = [COST_LAW.fit(fit_limits(f, 0.02)) for f in ("H11/c11", "H9/d9", "H8/e8", "H7/f7", "H7/g6")]
    assert costs == sorted(costs)
    assert COST_LAW.part(COST_LAW.reference) == pytest.approx(COST_LAW.a + COST_LAW.b)
