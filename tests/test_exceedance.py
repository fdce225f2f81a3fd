"""Exceedance probabilities: the event grammar, the Clopper-Pearson interval's coverage measured on
binomial draws, and pf requirements decided on its one-sided bounds (fail where the data already
refute the limit, pass where the bound allows, undecided between; exit codes 1/0/3)."""
import json

import numpy as np
import pytest
import xarray as xr
from scipy import stats as sps

from pipeline.analysis.estimators import clopper_pearson, one_sided_cp
from pipeline.analysis.exceedance import EventError, exceedance, format_exceedance, parse_event
from pipeline.analysis.gate import exit_code, judge
from pipeline.analysis.spec import SpecError, parse_spec
from pipeline.cli import main

DIRECTIONS = ["x", "y", "z", "rx", "ry", "rz"]
QUANTITIES = ["displacement", "velocity", "acceleration"]
CONF = 0.95
DRAWS = 20_000


def _ensemble(z, attrs=None) -> xr.Dataset:
    """An ensemble whose displacement z maxima are ``z`` (m), every other cell 1 um."""
    z = np.asarray(z, float)
    data = np.full((3, len(z), 6), 1e-6)
    data[0, :, 2] = z
    dims = ("quantity", "realization", "direction")
    return xr.Dataset({"max_abs_error": (dims, data), "mean_abs_error": (dims, data / 2),
                       "status": ("realization", np.array(["finished"] * len(z), dtype=object))},
                      coords={"quantity": QUANTITIES, "direction": DIRECTIONS,
                              "realization": np.arange(len(z))}, attrs=attrs or {})


def _with_exceeding(n: int, k: int) -> np.ndarray:
    """n maxima (m) of which the first k exceed 0.1 mm."""
    return np.where(np.arange(n) < k, 0.2e-3, 0.05e-3)


# --- the grammar -----------------------------------------------------------------------------------

def test_events_parse_to_si_with_their_window():
    e = parse_event("displacement:z>0.1mm")
    assert (e.quantity, e.directions, e.limit, e.window) == ("displacement", ("z",), pytest.approx(1e-4), "whole")
    v = parse_event("velocity:x > 2 mm/s/steady")
    assert (v.limit, v.unit, v.window) == (pytest.approx(2e-3), "mm/s", "steady")
    assert parse_event("acceleration:y>1m/s^2").window == "whole"


def test_an_event_over_several_directions_is_their_union():
    """'displacement:x,y,z>0.05mm': the platform leaves its 0.05 mm box in some direction; a realisation
    is in it when any direction's maximum exceeds the limit, so P is at least each direction's and at
    most their sum."""
    e = parse_event("displacement:x,y,z>0.05mm/steady")
    assert (e.directions, e.window, e.direction_words) == (("x", "y", "z"), "steady", "any of x, y, z")
    ds = _ensemble(np.zeros(400))
    values = np.random.default_rng(3).uniform(0, 1e-4, (400, 3))     # x, y, z maxima (m)
    ds["max_abs_error"][0, :, :3] = values
    union = exceedance(ds, parse_event("displacement:x,y,z>0.05mm"))
    each = [exceedance(ds, parse_event(f"displacement:{d}>0.05mm")).exceeding for d in "xyz"]
    assert union.exceeding == int(np.count_nonzero((values > 5e-5).any(axis=-1))) and union.n == 400
    assert max(each) < union.exceeding < sum(each) and union.directions == ("x", "y", "z")
    assert "P(displacement:x,y,z>0.05mm) (any of x, y, z) over the whole run = " in format_exceedance([union])


@pytest.mark.parametrize("text, token", [
    ("displacement:z>0.1", "missing unit"), ("force:z>1mm", "unknown quantity 'force'"),
    ("displacement:w>1mm", "unknown direction 'w'"), ("displacement:z>1mm/stedy", "unknown window 'stedy'"),
    ("displacement:z<1mm", "an event reads"), ("displacement:x,rz>1mm", "mix translations and rotations"),
    ("displacement:z>1rad", "unknown unit 'rad'"), ("displacement:z>0.5mm@q95", "an event has no @statistic"),
    ("displacement:z>nanmm", "value 'nan' is not a positive finite number"),
    ("displacement:z>1e999mm", "value '1e999' is not a positive finite number"),
    ("displacement:z>mm", "missing value after '>'")])
def test_malformed_events_name_the_bad_token(text, token):
    with pytest.raises(EventError, match="^--event ") as info:
        parse_event(text)
    assert token in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("text, token", [
    ("displacement:z>=0.1mm@pf<=1e-3", "use <= or <"), ("displacement:z<=0.1mm@pf<=1.5", "strictly between"),
    ("displacement:z<=0.1mm@pf>=1e-3", "pf<=P or pf<P"), ("displacement:z<=0.1mm@pf<=x", "not a number")])
def test_malformed_pf_requirements_name_the_bad_token(text, token):
    with pytest.raises(SpecError, match=token):
        parse_spec(text)


# --- the interval ------------------------------------------------------------------------------------

@pytest.mark.parametrize("n, p", [(20, 0.05), (100, 0.01), (1000, 1e-3), (3000, 1e-3), (20000, 1e-4),
                                  (50, 0.5)])
def test_clopper_pearson_covers_at_least_its_confidence_on_binomial_draws(n, p):
    """Over 20 000 binomial draws the two-sided interval and each one-sided bound cover p at least at
    the stated confidence minus three standard errors of the coverage estimate."""
    k = np.random.default_rng(40).binomial(n, p, DRAWS)
    lower, upper = clopper_pearson(k, n, CONF)
    slack = 3 * np.sqrt(CONF * (1 - CONF) / DRAWS)
    assert np.mean((lower <= p) & (p <= upper)) >= CONF - slack
    low1, up1 = one_sided_cp(k, n, CONF)
    assert np.mean(low1 <= p) >= CONF - slack and np.mean(p <= up1) >= CONF - slack


def test_clopper_pearson_bounds_are_the_beta_quantiles_and_the_closed_form_at_zero():
    """k = 0: the upper one-sided bound solves (1 - p)^n = 1 - c; else the Beta quantiles."""
    low, up = one_sided_cp(0, 3000, CONF)
    assert low == 0 and up == pytest.approx(1 - (1 - CONF) ** (1 / 3000), rel=1e-10)
    low, up = one_sided_cp(7, 50, CONF)
    assert sps.binom.sf(6, 50, low) == pytest.approx(1 - CONF) and sps.binom.cdf(7, 50, up) == pytest.approx(1 - CONF)


def test_exceedance_of_an_ensemble_counts_the_maxima_above_the_limit():
    r = exceedance(_ensemble(_with_exceeding(400, 4)), parse_event("displacement:z>0.1mm"))
    assert (r.exceeding, r.n, r.estimate) == (4, 400, 0.01)
    assert (r.lower, r.upper) == tuple(pytest.approx(float(b)) for b in clopper_pearson(4, 400, CONF))


def test_a_qmc_file_is_refused():
    with pytest.raises(ValueError, match="QMC"):
        exceedance(_ensemble(_with_exceeding(64, 1), {"sampler": "qmc"}), parse_event("displacement:z>0.1mm"))


# --- pf requirements ---------------------------------------------------------------------------------

SPEC = parse_spec("displacement:z<=0.1mm@pf<=1e-3")


@pytest.mark.parametrize("n, k", [(20, 1), (50, 5), (500, 3)])
def test_a_pf_requirement_fails_at_small_n_where_the_data_refute_it(n, k):
    """Were P <= 1e-3, k or more of n would exceed with probability P(Bin(n, 1e-3) >= k) < 5 %."""
    (v,) = judge(SPEC, _ensemble(_with_exceeding(n, k)))
    assert sps.binom.sf(k - 1, n, 1e-3) < 1 - CONF
    assert v.outcome == "fail" and v.lower > 1e-3 and exit_code([v]) == 1


def test_a_pf_requirement_passes_from_the_n_where_the_bound_allows_and_is_undecided_before():
    """No exceedance in n: the upper bound 1 - 0.05^(1/n) is <= 1e-3 from n = 2995 on."""
    first = int(np.ceil(np.log(1 - CONF) / np.log(1 - 1e-3)))
    assert first == 2995
    (v,) = judge(SPEC, _ensemble(_with_exceeding(first - 1, 0)))
    assert (v.outcome, v.n_needed) == ("undecided", first) and exit_code([v]) == 3
    (w,) = judge(SPEC, _ensemble(_with_exceeding(first, 0)))
    assert w.outcome == "pass" and w.upper <= 1e-3 and exit_code([w]) == 0


def test_a_pf_requirement_with_one_exceedance_in_a_few_hundred_is_undecided():
    (v,) = judge(SPEC, _ensemble(_with_exceeding(300, 1)))
    assert v.outcome == "undecided" and v.lower < 1e-3 < v.upper and v.n_needed > 300


@pytest.fixture(scope="module")
def smoke_file(tmp_path_factory):
    """40 quasi-static realisations of the smoke scene (about 10 s)."""
    path = tmp_path_factory.mktemp("smoke") / "s.nc"
    assert main(["run", "smoke", "-n", "40", "--model", "quasi-static", "-o", str(path)]) == 0
    return path


def test_stats_prints_the_event_probability_and_judges_pf_with_exit_codes(smoke_file, capsys):
    """End to end: --event counts the file's maxima over the limit (the median here, so about half);
    a pf <= 1e-3 requirement fails (exit 1), pf <= 0.9 passes (exit 0), one-sided bounds as judge's."""
    from pipeline.files.opening import open_ensemble
    z = open_ensemble(smoke_file)["max_abs_error"].sel(quantity="displacement", direction="z", window="whole")
    limit_mm = float(np.median(z.values)) * 1e3
    k = int(np.count_nonzero(z.values > limit_mm * 1e-3))
    capsys.readouterr()
    code = main(["stats", str(smoke_file), "--event", f"displacement:z>{limit_mm!r}mm", "--json",
                 "--require", f"displacement:z<={limit_mm!r}mm@pf<=1e-3"])
    out = json.loads(capsys.readouterr().out)
    (e,) = out["exceedance"]
    assert (e["exceeding"], e["n"]) == (k, 40) and 0 < k < 40 and e["lower"] < k / 40 < e["upper"]
    assert e["window"] == "whole"
    assert out["requirements"][0]["outcome"] == "fail" and code == 1
    assert main(["stats", str(smoke_file), "--require", f"displacement:z<={limit_mm!r}mm@pf<=0.9"]) == 0
    assert main(["stats", str(smoke_file), "--require", f"displacement:z<={limit_mm!r}mm@pf<=0.5"]) == 3
    capsys.readouterr()
    assert main(["stats", str(smoke_file), "--event", "displacement:z>1mm/stedy"]) == 2
    assert "unknown window 'stedy'" in capsys.readouterr().err
    events = ["--event", "displacement:z>1mm", "--event", "displacement:z>1mm/steady"]
    assert main(["stats", str(smoke_file), *events]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("P(")]
    assert [ln.split(" = ")[0] for ln in lines] == ["P(displacement:z>1mm) over the whole run",
                                                    "P(displacement:z>1mm/steady) over the steady window"]


def test_failed_realisations_widen_the_interval_to_either_outcome():
    """40 draws, 6 finished in the event, 30 finished out of it, 4 failed: the estimate is 6/36 over the
    finished ones; the interval is exact over all 40 whatever the failed ones were, its lower end the
    Clopper-Pearson bound of 6/40 and its upper end that of 10/40 (scipy's exact binomial interval,
    an independent computation), and the line says how the failed ones are counted."""
    ds = _ensemble(_with_exceeding(40, 6))
    ds["status"][36:] = "diverged"
    r = exceedance(ds, parse_event("displacement:z>0.1mm"))
    assert (r.exceeding, r.n, r.n_failed) == (6, 36, 4) and r.estimate == pytest.approx(6 / 36)
    low = sps.binomtest(6, 40).proportion_ci(CONF, method="exact").low
    high = sps.binomtest(10, 40).proportion_ci(CONF, method="exact").high
    assert (r.lower, r.upper) == (pytest.approx(low, rel=1e-9), pytest.approx(high, rel=1e-9))
    assert "the interval counts them out on its lower side and in on its upper one" in format_exceedance([r])


def test_an_event_on_one_run_repeated_is_exact_as_the_gate_says(tmp_path, capsys):
    """A file whose realisations are all one run (elastic level, nothing drawn): P is 0 or 1 exactly, as the
    gate's exact rule has it; a Clopper-Pearson [0.025, 1] of 1 of 1 said otherwise (a reviewer's find)."""
    single = tmp_path / "elastic.nc"
    assert main(["simulate", "smoke", "--model", "elastic", "-o", str(single)]) == 0
    capsys.readouterr()
    for event, p in (("displacement:z>0.001mm", 1.0), ("displacement:z>1m", 0.0)):
        assert main(["stats", str(single), "--event", event, "--json"]) == 0
        (r,) = json.loads(capsys.readouterr().out)["exceedance"]
        assert (r["estimate"], r["lower"], r["upper"]) == (p, p, p) and r["method"].startswith("exact"), r
