"""What fails (pipeline.analysis.failure_domain), verified on linear limit states alpha . z > beta in
standard normal space, whose failure domain is known: z given failure has mean alpha phi(beta) /
Phi(-beta) (along the design point beta alpha) and std 1 across alpha; the most probable failing
point tends to beta alpha. Then `rss6 reliability --json --plot` end to end on the smoke scene."""
import json
import re

import numpy as np
import pytest
from scipy import stats as sps

from pipeline.analysis.failure_domain import failure_domain, format_failure_domain
from pipeline.analysis.subset import SubsetSettings, subset_simulation
from pipeline.cli import main
from pipeline.files.reading import load_netcdf

ALPHA = np.array([0.6, 0.8, 0.0])
LABELS, GROUPS = ("a", "b", "c"), ("first", "first", "second")


def _shift(beta: float) -> float:
    """E[t | t > beta] for t standard normal: phi(beta) / Phi(-beta)."""
    return sps.norm.pdf(beta) / sps.norm.sf(beta)


def test_independent_draws_shift_along_alpha_by_the_truncated_normal_mean():
    """Plain Monte Carlo, 400,000 draws, beta = 2 (about 9,100 failing): the mean is alpha times
    phi(beta) / Phi(-beta) within 4 standard errors, the std across alpha is 1."""
    z = np.random.default_rng(5).standard_normal((400_000, 3))
    failing = z @ ALPHA > 2.0
    fd = failure_domain(z, np.zeros(len(z), int), failing, LABELS, GROUPS)
    n, lam = failing.sum(), _shift(2.0)
    var_t = 1 + 2.0 * lam - lam ** 2                  # variance of t given t > beta = 2
    std = np.sqrt(ALPHA ** 2 * var_t + 1 - ALPHA ** 2)    # per input: along alpha narrowed, across it 1
    assert fd.failing == n and fd.level == 0
    assert np.all(np.abs(fd.mean - ALPHA * lam) < 4 * std / np.sqrt(n))
    assert fd.std == pytest.approx(std, abs=0.03)
    assert [g for g, _, _ in fd.group_shifts()] == ["first", "second"]
    assert fd.group_shifts()[0][1] == pytest.approx(np.sqrt(np.mean((ALPHA[:2] * _shift(2.0)) ** 2)), rel=0.02)
    best = z[fd.most_probable]
    assert failing[fd.most_probable] and np.linalg.norm(best) == pytest.approx(2.0, abs=0.02)
    assert best @ ALPHA / np.linalg.norm(best) > 0.99                # near the design point 2 alpha


def test_subset_states_of_the_last_level_shift_along_the_design_point():
    """Subset simulation of P = Phi(-3.09) = 1e-3: the failing states of its last level are spread
    as the failure domain is (their chains correlated: a looser tolerance than independent draws)."""
    beta = 3.09
    res = subset_simulation(lambda z: z @ ALPHA, 3, beta, SubsetSettings(1000, 0.1, seed=2))
    ev = res.evaluations
    fd = failure_domain(ev.z, ev.level, ev.response > beta, LABELS, GROUPS)
    assert fd.level == len(res.levels) - 1 and fd.failing >= 50
    assert fd.mean @ ALPHA == pytest.approx(_shift(beta), abs=0.15)
    assert np.linalg.norm(fd.mean - (fd.mean @ ALPHA) * ALPHA) < 0.4
    best = fd.most_probable_z
    assert beta <= np.linalg.norm(best) < beta + 0.3 and best @ ALPHA / np.linalg.norm(best) > 0.95


def test_inputs_no_draw_uses_are_not_ranked_and_a_ranking_within_their_noise_is_said():
    """Inputs of family 'unused' (nominal sizes: taken, not used) cannot drive a failure, so they are
    not listed as the inputs of largest shift nor as the design point's largest |z_i| (a new user's
    review found B_size[leg 5] at the top); when no family shifts more than they do, the text says
    the ranking is noise."""
    rng = np.random.default_rng(3)
    z = rng.standard_normal((4000, 4))
    labels, groups = ("a", "b", "B_size[leg 5]", "B_size[leg 6]"), ("first", "second", "unused", "unused")
    driven = failure_domain(z, np.zeros(4000, int), z[:, 0] > 1.0, labels, groups)
    text = format_failure_domain(driven)
    listed = text.split("inputs of largest shift: ")[1].split("\n")[0]
    assert "B_size" not in listed and "B_size" not in text.split("largest |z_i|: ")[1]
    assert listed.startswith("a mean +1.") and "the ranking is noise" not in text
    families = text.split("mean shifts: ")[1].split("\n")[0]
    assert "unused" not in families and families.startswith("first ")   # the noise is said, not ranked
    assert re.search(r"noise: the unused inputs' shift is 0\.0\d .*not well above it is not resolved", text)
    noise = failure_domain(z, np.zeros(4000, int), z[:, 2] > 1.0, labels, groups)   # only 'unused' drives it
    assert "the ranking is noise at this sample" in format_failure_domain(noise)


def test_nothing_failing_is_refused():
    with pytest.raises(ValueError, match="no evaluation is in the event"):
        failure_domain(np.zeros((3, 3)), np.zeros(3, int), np.zeros(3, bool), LABELS, GROUPS)


def test_reliability_prints_what_fails_and_draws_its_figure(tmp_path, capsys):
    out, png = tmp_path / "s.nc", tmp_path / "s.png"
    capsys.readouterr()
    assert main(["reliability", "smoke", "--event", "displacement:z>0.2mm", "-n", "200", "--workers", "1",
                 "-o", str(out), "--plot", str(png), "--json"]) == 0
    fd = json.loads(capsys.readouterr().out)["failure_domain"]
    assert png.stat().st_size > 10_000
    ds = load_netcdf(out)
    z, level = ds["z"].values, ds["level"].values
    failing = ds["max_abs_error"].sel(quantity="displacement", direction="z").values > 2e-4
    assert fd["level"] == level.max() and fd["failing"] == np.count_nonzero(failing & (level == level.max()))
    mean = z[failing & (level == level.max())].mean(axis=0)
    assert [i["mean"] for i in fd["inputs"]] == pytest.approx(mean.tolist())
    assert fd["most_probable"]["norm"] == pytest.approx(np.linalg.norm(z[failing], axis=1).min())
    assert {i["family"] for i in fd["inputs"]} >= {"C_magnitude", "B_polar", "A_radial_angle"}
    # the smoke scene's sizes are nominal: their uniforms are taken but unused
    assert {i["family"] for i in fd["inputs"] if i["input"].startswith("C_size")} == {"unused"}
    assert len(fd["inputs"]) == z.shape[1] == 78
    rows = {r["input"]: r for r in fd["most_probable"]["inputs"]}
    assert rows["C_size (legs 1-6)"]["units"] == "m" and len(rows["|e_B| (legs 1-6)"]["values"]) == 6
    # the same figure again, to another -o: refused by the option that named it (it said "another -o")
    assert main(["reliability", "smoke", "--event", "displacement:z>0.2mm", "-n", "200", "--workers", "1",
                 "-o", str(tmp_path / "t.nc"), "--plot", str(png)]) == 2
    assert capsys.readouterr().err.strip().endswith("(remove it or choose another --plot)")
