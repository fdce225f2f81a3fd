"""The README's numbers whose commands take seconds, pinned to about 1 % (each test runs the README's command).

A change that moves one of them fails here and says which README line to update with the new value."""
import json
import re

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.files.reading import load_netcdf

SPEC = "displacement:x,y,z<=0.1mm@q95"


def _readme_says(text: str) -> None:
    from tests.test_readme import README
    assert text in " ".join(README.read_text().split()), f"README no longer says {text!r}: update this test with it"


def test_budget_of_the_paper_robot_is_the_readmes(tmp_path, capsys):
    """README: `rss6 budget paper --spec "displacement:x,y,z<=0.1mm@q95"` ... (0.2811)."""
    assert main(["budget", "paper", "--spec", SPEC, "--workers", "1", "-o", str(tmp_path / "b")]) == 0
    scale = float(re.search(r"largest common clearance scale factor: ([0-9.]+)", capsys.readouterr().out).group(1))
    _readme_says("(0.2811)")
    assert scale == pytest.approx(0.2811, rel=0.01)


def test_allocation_of_the_paper_robot_is_the_readmes(tmp_path, capsys):
    """README: revolute H9/e9, spherical C H9/e9, B H10/d10: cost 48.09 against 49.85 for H9/e9 everywhere."""
    assert main(["allocate", "paper", "--spec", SPEC, "--workers", "1", "--json", "-o", str(tmp_path / "a")]) == 0
    out = json.loads(capsys.readouterr().out)
    _readme_says("cost 48.09 against 49.85 for H9/e9 everywhere")
    assert out["total_cost"] == pytest.approx(48.09, rel=0.01)
    assert out["uniform_cost"] == pytest.approx(49.85, rel=0.01) and out["uniform_class"] == "H9/e9"
    assert {c["family"]: c["class"] for c in out["classes"]} == {
        "revolute_radial": "H9/e9", "spherical_C": "H9/e9", "spherical_B": "H10/d10"}


def test_reliability_of_the_paper_robot_is_the_readmes(tmp_path, capsys):
    """README: P = 1.33e-3 [6.6e-4, 3.2e-3] in 2,800 evaluations (subset simulation, quasi-static level)."""
    assert main(["reliability", "paper", "--model", "quasi-static", "--event", "displacement:z>0.285mm",
                 "--workers", "1", "--json", "-o", str(tmp_path / "r.nc")]) == 0
    out = json.loads(capsys.readouterr().out)
    _readme_says("1.33e-3 [6.6e-4, 3.2e-3]")
    assert out["pf"] == pytest.approx(1.33e-3, rel=0.01) and out["lower"] == pytest.approx(6.6e-4, rel=0.01)
    assert out["upper"] == pytest.approx(3.2e-3, rel=0.02)   # 3.151e-3 rounded to two digits in the README
    assert out["evaluations"] == 2800


def test_workspace_worst_case_of_the_paper_robot_is_the_readmes(tmp_path, capsys):
    """README: on the paper robot's default grid the worst case in x is 1.56-1.67 mm."""
    assert main(["map", "paper", "-o", str(tmp_path / "m")]) == 0
    worst = load_netcdf(tmp_path / "m" / "workspace_map.nc")["worst_case_translation"].sel(translation="x").values
    _readme_says("1.56-1.67 mm")
    assert (np.nanmin(worst), np.nanmax(worst)) == (pytest.approx(1.56e-3, rel=0.01), pytest.approx(1.67e-3, rel=0.01))


def test_geometric_error_against_the_clearance_error_is_the_readmes(tmp_path):
    """README: the geometric error is 1.7-2.3x the clearance error (q50, steady; docs/results.md's table, whose
    ratios are 2.33, 1.82, 1.83, 1.70, 2.02, 1.82)."""
    from pipeline.analysis.stats import ensemble_stats
    from pipeline.files.opening import open_ensemble
    q50 = []
    for scene, level in (("paper_manufacturing", "rigid"), ("paper_tolerance", "quasi-static")):
        path = tmp_path / f"{scene}.nc"
        assert main(["run", scene, "--model", level, "-n", "256", "--workers", "1", "-o", str(path)]) == 0
        sds = ensemble_stats(open_ensemble(path), window="steady")
        q50.append(sds["max_abs_error"].sel(statistic="q50", bound="estimate", quantity="displacement").values)
    ratio = q50[0] / q50[1]
    _readme_says("the geometric error is 1.7-2.3x the clearance error")
    np.testing.assert_allclose(ratio, [2.33, 1.82, 1.83, 1.70, 2.02, 1.82], rtol=0.01)
