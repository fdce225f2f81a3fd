"""`--require` end to end on the smoke scene's quasi-static level: the README's CI recipe passes,
a limit far below fails, one at the sample median is undecided with the n it would need, a
malformed spec costs nothing, and the same seed gives the same verdicts and the same file."""
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.store import open_ensemble

README = Path(__file__).resolve().parents[1] / "README.md"


def _recipe() -> list[str]:
    """The `rss6 run` command of the README's CI recipe, as argv."""
    text = README.read_text()
    block = re.search(r"### CI recipe.*?```bash\n(.*?)```", text, re.S)
    assert block, "README has no '### CI recipe' section with a bash block"
    joined = block.group(1).replace("\\\n", " ")
    (line,) = [ln for ln in joined.splitlines() if ln.strip().startswith("rss6 run")]
    return shlex.split(line.split("#")[0])


def _rss6(args, cwd) -> subprocess.CompletedProcess:
    exe = shutil.which("rss6")
    cmd = [exe] if exe else [sys.executable, "-m", "pipeline.cli"]
    return subprocess.run(cmd + list(args), cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def recipe_run(tmp_path_factory):
    """The recipe's command, run as written, in a fresh folder."""
    cwd = tmp_path_factory.mktemp("recipe")
    argv = _recipe()
    proc = _rss6(argv[1:], cwd)
    output = cwd / argv[argv.index("-o") + 1]
    return proc, output, argv


def test_readme_ci_recipe_passes_and_records_its_verdicts(recipe_run):
    proc, output, argv = recipe_run
    assert "--require" in argv and "smoke" in argv
    assert proc.returncode == 0, proc.stderr
    assert "verdict: pass" in proc.stdout
    ds = open_ensemble(output)
    assert ds.attrs["requirements_verdict"] == "pass"
    recorded = json.loads(ds.attrs["requirements"])
    assert {v["outcome"] for v in recorded} == {"pass"} and len(recorded) == 6


def test_same_seed_gives_the_same_verdicts_and_the_same_file(recipe_run, tmp_path):
    proc, output, argv = recipe_run
    again = _rss6(argv[1:], tmp_path)
    assert again.returncode == 0 and again.stdout.split("requirements")[1] == \
        proc.stdout.split("requirements")[1]
    assert (tmp_path / output.name).read_bytes() == output.read_bytes()


def _stats_json(output, *specs, extra=()):
    args = ["stats", str(output), "--json", *extra]
    for s in specs:
        args += ["--require", s]
    proc = _rss6(args, output.parent)
    return proc, json.loads(proc.stdout, parse_constant=lambda c: pytest.fail(f"non-JSON {c}"))


def test_a_limit_far_below_fails(recipe_run):
    _, output, _ = recipe_run
    proc, out = _stats_json(output, "displacement:x,y,z<=1um@q95")
    assert proc.returncode == 1
    assert {v["outcome"] for v in out["requirements"]} == {"fail"}


def test_a_limit_at_the_sample_median_is_undecided_with_the_n_it_needs(recipe_run):
    _, output, _ = recipe_run
    ds = open_ensemble(output)
    x = ds["max_abs_error"].sel(quantity="displacement", direction="x").values
    spec = f"displacement:x<={float(np.median(x)) * 1e3:.3g}mm@q50"   # as read off the table
    proc, out = _stats_json(output, spec)
    (v,) = out["requirements"]
    assert proc.returncode == 1 and v["outcome"] == "undecided"
    assert v["lower"] < v["limit"] < v["upper"]
    assert v["n_needed"] > v["n"] == ds.sizes["realization"]
    proc, _ = _stats_json(output, spec, extra=["--undecided", "pass"])
    assert proc.returncode == 0
    table = _rss6(["stats", str(output), "--require", spec], output.parent).stdout
    (row,) = [ln for ln in table.splitlines() if ln.startswith(spec[:30]) and " x " in ln]
    assert row.split()[-2:] == ["undecided", str(v["n_needed"])]


@pytest.mark.parametrize("spec, token", [
    ("displacment:x<=1mm@q95", "unknown quantity 'displacment'"),
    ("displacement:w<=1mm@q95", "unknown direction 'w'"),
    ("displacement:x<=1mm@q97", "unknown statistic 'q97'"),
    ("displacement:x<=1parsec@q95", "unknown unit 'parsec'"),
    ("displacement:x==1mm@q95", "unknown operator '=='"),
    ("displacement:x<=mm@q95", "missing value"),
])
def test_malformed_spec_is_one_line_exit_2_and_computes_nothing(tmp_path, spec, token):
    proc = _rss6(["run", "smoke", "-n", "4", "--model", "quasi-static", "-o", "x.nc",
                  "--require", spec], tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and token in lines[0] and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
