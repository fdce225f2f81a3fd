"""Requirement specs: the grammar, unit conversion, and verdicts from a statistics Dataset."""
import math

import numpy as np
import pytest
import xarray as xr

from pipeline.gate import exit_code, format_verdicts, judge, judge_all
from pipeline.spec import STANDARD_GRAVITY, SpecError, parse_spec
from pipeline.stats import MIN_N_STD, min_n_for_quantile

DIRECTIONS = ["x", "y", "z", "rx", "ry", "rz"]


@pytest.mark.parametrize("text, quantity, dirs, op, limit, stat, measure", [
    ("displacement:x,y<=0.05mm@q95", "displacement", ("x", "y"), "<=", 5e-5, "q95", "max"),
    ("acceleration:z<=50m/s^2@q50", "acceleration", ("z",), "<=", 50.0, "q50", "max"),
    (" velocity : rx , ry < 2 mrad/s @ mean:mean ", "velocity", ("rx", "ry"), "<", 2e-3, "mean",
     "mean"),
    ("acceleration:x>=0.5g@q50", "acceleration", ("x",), ">=", 0.5 * STANDARD_GRAVITY, "q50", "max"),
    ("velocity:z=<3 m s-1@q05", "velocity", ("z",), "<=", 3.0, "q05", "max"),
    ("displacement:rz<1deg@std", "displacement", ("rz",), "<", math.pi / 180, "std", "max"),
    ("acceleration:y<2e3mm/s2@q99", "acceleration", ("y",), "<", 2.0, "q99", "max"),
    ("displacement:all<=1um@q95", "displacement", ("x", "y", "z", "rx", "ry", "rz"), "<=", 1e-6,
     "q95", "max"),
])
def test_valid_specs_parse_to_si(text, quantity, dirs, op, limit, stat, measure):
    if dirs == tuple(DIRECTIONS):   # 'all' with a length unit mixes rotations: refused
        with pytest.raises(SpecError, match="mix translations and rotations"):
            parse_spec(text)
        return
    s = parse_spec(text)
    assert (s.quantity, s.directions, s.op, s.statistic, s.measure) == (quantity, dirs, op, stat,
                                                                         measure)
    assert s.limit == pytest.approx(limit, rel=1e-12)
    assert s.window is None


def test_window_is_parsed():
    s = parse_spec("displacement:x<=0.1mm@q95/steady")
    assert (s.statistic, s.window) == ("q95", "steady")


@pytest.mark.parametrize("text, token", [
    ("displacment:x<=0.05mm@q95", "unknown quantity 'displacment'"),
    ("displacement:q<=0.05mm@q95", "unknown direction 'q'"),
    ("displacement:x<=0.05mm@q90", "unknown statistic 'q90'"),
    ("displacement:x<=0.05furlong@q95", "unknown unit 'furlong'"),
    ("displacement:x<=0.05mm/s@q95", "unknown unit 'mm/s'"),
    ("displacement:rx<=0.05mm@q95", "unknown unit 'mm'"),
    ("displacement:x=0.05mm@q95", "unknown operator '='"),
    ("displacement:x!=0.05mm@q95", "unknown operator '!='"),
    ("displacement:x 0.05mm@q95", "missing operator"),
    ("displacement:x<=mm@q95", "missing value"),
    ("displacement:x<=0.05@q95", "missing unit"),
    ("displacement:x<=0.05mm", "missing '@STATISTIC'"),
    ("displacement<=0.05mm@q95", "missing directions"),
    ("displacement:x,rx<=0.05mm@q95", "mix translations and rotations"),
    ("displacement:x<=0.05mm@q95:median", "unknown measure 'median'"),
    ("displacement:x<=0.05mm@q95/", "missing window name"),
    ("displacement:x<=0.05mm@max", "statistic 'max' has no confidence interval"),
])
def test_malformed_specs_name_the_bad_token(text, token):
    with pytest.raises(SpecError) as err:
        parse_spec(text)
    message = str(err.value)
    assert token in message and "\n" not in message
    assert repr(text) in message


def _stats(estimate, lower, upper, n=100, confidence=0.95):
    """A statistics Dataset as pipeline.stats writes it, with one interval for every cell."""
    stat = ["mean", "std", "q05", "q50", "q95", "q99", "max"]
    data = np.empty((len(stat), 3, 3, 6))
    data[:, 0], data[:, 1], data[:, 2] = estimate, lower, upper
    coords = {"statistic": stat, "bound": ["estimate", "lower", "upper"],
              "quantity": ["displacement", "velocity", "acceleration"], "direction": DIRECTIONS}
    dims = ("statistic", "bound", "quantity", "direction")
    return xr.Dataset({"max_abs_error": (dims, data), "mean_abs_error": (dims, data / 2)},
                      coords=coords, attrs={"n_finished": n, "n_failed": 0,
                                            "confidence": confidence})


@pytest.mark.parametrize("limit_mm, outcome", [(0.2, "pass"), (0.04, "fail"), (0.1, "undecided"),
                                               (0.12, "undecided")])
def test_verdict_is_where_the_interval_lies(limit_mm, outcome):
    stats = _stats(1.0e-4, 0.8e-4, 1.3e-4)
    (v,) = judge(parse_spec(f"displacement:x<={limit_mm}mm@q95"), stats)
    assert v.outcome == outcome
    (w,) = judge(parse_spec(f"displacement:x>{limit_mm}mm@q95"), stats)
    assert w.outcome == {"pass": "fail", "fail": "pass"}.get(outcome, "undecided")


def test_failed_realisations_make_a_met_limit_undecided_not_passed():
    """The intervals cover the finished realisations only: with 30 of 64 failed (the failed draws
    are in the population), a limit the whole interval meets is undecided, with no n that decides;
    a violated one still fails; the table says why."""
    stats = _stats(1.0e-4, 0.8e-4, 1.3e-4, n=34).assign_attrs(n_failed=30)
    (v,) = judge(parse_spec("displacement:x<=0.2mm@mean"), stats)
    assert (v.outcome, v.n_needed, v.n_failed) == ("undecided", None, 30)
    assert "30 of 64 realisations failed" in v.reason
    (w,) = judge(parse_spec("displacement:x<=0.05mm@mean"), stats)
    assert w.outcome == "fail"
    assert exit_code([v]) == 1 and exit_code([v], undecided="pass") == 0
    assert "30 failed, so a limit they meet is undecided" in format_verdicts([v, w])
    assert format_verdicts([v]).splitlines()[0].endswith("; estimate and interval in the unit of the spec's limit)")
    (p,) = judge(parse_spec("displacement:x<=0.2mm@mean"), stats.assign_attrs(n_failed=0))
    assert p.outcome == "pass"


def test_n_to_decide_follows_the_interval_shrinkage():
    stats = _stats(1.0e-4, 0.8e-4, 1.3e-4, n=100)
    (v,) = judge(parse_spec("displacement:x<=0.12mm@q95"), stats)
    # upper half-width 0.3e-4 must shrink to the margin 0.2e-4: n * (0.3/0.2)^2 = 225
    assert v.n_needed == 225
    (w,) = judge(parse_spec("displacement:x<=0.09mm@q95"), stats)   # 0.2e-4 below, margin 0.1e-4
    assert w.n_needed == 400
    (u,) = judge(parse_spec("displacement:x<=0.1mm@q95"), stats)    # at the estimate: none
    assert u.outcome == "undecided" and u.n_needed is None


def test_missing_interval_is_undecided_with_the_smallest_n_that_has_one():
    stats = _stats(1.0e-4, np.nan, np.nan, n=32)
    (v,) = judge(parse_spec("displacement:x<=10mm@q95"), stats)
    assert v.outcome == "undecided" and v.lower is None
    assert v.n_needed == min_n_for_quantile(0.95, 0.95) == 59
    (m,) = judge(parse_spec("displacement:x<=10mm@std"), _stats(1.0e-4, np.nan, np.nan, n=32))
    assert m.n_needed == MIN_N_STD


def test_spec_verdicts_cover_every_direction_and_exit_codes():
    stats = _stats(1.0e-4, 0.8e-4, 1.3e-4)
    stats["max_abs_error"].loc[{"direction": "y"}] = [[5e-4], [4e-4], [6e-4]]
    verdicts = judge_all([parse_spec("displacement:x,y,z<=0.2mm@q95")], stats)
    assert [v.outcome for v in verdicts] == ["pass", "fail", "pass"]
    assert exit_code(verdicts) == 1
    assert exit_code([v for v in verdicts if v.direction != "y"]) == 0
    undecided = judge_all([parse_spec("displacement:x<=0.1mm@q95")], stats)
    assert exit_code(undecided) == 1 and exit_code(undecided, undecided="pass") == 0
    table = format_verdicts(verdicts)
    assert "verdict: fail" in table and "0.5" in table   # y's estimate in mm


def test_mean_measure_reads_the_mean_variable():
    stats = _stats(1.0e-4, 0.8e-4, 1.3e-4)     # mean_abs_error holds half of these
    (v,) = judge(parse_spec("displacement:x<=0.07mm@q95:mean"), stats)
    assert v.outcome == "pass" and v.estimate == pytest.approx(0.5e-4)


def test_window_must_exist_in_the_statistics():
    with pytest.raises(ValueError, match="no analysis windows"):
        judge(parse_spec("displacement:x<=0.1mm@q95/steady"), _stats(1e-4, 0.8e-4, 1.3e-4))
    stats = xr.concat([_stats(1e-4, 0.8e-4, 1.3e-4), _stats(1e-5, 0.8e-5, 1.3e-5)],
                      dim=xr.DataArray(["startup", "steady"], dims="window", name="window"))
    stats.attrs.update(n_finished=100, confidence=0.95)
    (v,) = judge(parse_spec("displacement:x<=0.05mm@q95/steady"), stats)
    assert v.outcome == "pass" and v.window == "steady"
    with pytest.raises(ValueError, match="unknown window 'settled'"):
        judge(parse_spec("displacement:x<=0.1mm@q95/settled"), stats)
