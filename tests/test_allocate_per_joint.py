"""rss6 allocate --per-joint (quasi-static): the per-joint optimum against a brute force of simulations,
the greedy descent's local optimality, the per-family responses as sums of the per-joint ones, and
the command's file and refusals."""
from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from pipeline.analysis.spec import parse_spec
from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec
from pipeline.studies.allocation import ALLOCATED, class_options, responses
from pipeline.studies.allocation_joints import (joint_labels, joint_responses, joint_search, joint_uppers,
                                                verify_per_joint)

SPEC = "displacement:x,y,z<=0.04mm@q50"   # between all revolute joints at H8/f7 (x 0.029 mm) and at H10/d10 (0.052)
N = 20


@pytest.fixture(scope="module")
def paper(configs):
    return EnsembleSpec((configs / "paper.toml").read_text(), "paper", "quasi-static", "newmark", 1e-3, 4, 0)


@pytest.fixture(scope="module")
def joint_res(paper):
    return joint_responses(paper, [parse_spec(SPEC)], N)


def _two_revolute_classes(scene):
    """H8/f7 or H10/d10 for each revolute journal, H8/f7 for every ball joint: 2^6 = 64 combinations."""
    options = class_options(scene, ("H8/f7", "H10/d10"))
    return {f: options[f] if f == "revolute_radial" else options[f][:1] for f in ALLOCATED}


def test_family_responses_are_the_sums_of_the_joint_ones(paper, joint_res):
    family = responses(paper, [parse_spec(SPEC)], N)
    assert np.allclose(joint_res.family().offset, family.offset, rtol=1e-9, atol=1e-12)
    assert np.allclose(joint_res.family().spread, family.spread, rtol=1e-9, atol=1e-12)


def test_per_joint_optimum_equals_a_brute_force_of_simulations(paper, joint_res, tmp_path):
    """All 64 combinations simulated at their per-joint sizes and judged by the gate: the search's
    answer has the least passing cost, and a passing combination mixes the two revolute classes."""
    specs, scene = [parse_spec(SPEC)], paper.scene()
    options = _two_revolute_classes(scene)
    found = joint_search(joint_res, options, specs, scene, 0.95)
    combo, method, family = found.combo, found.method, found.family_combo
    assert "exhaustive" in method
    costs = {}
    for k, revolute in enumerate(itertools.product(*[options["revolute_radial"]] * 6)):
        candidate = revolute + (options["spherical_C"][0],) * 6 + (options["spherical_B"][0],) * 6
        verdicts = verify_per_joint(paper, specs, N, candidate, tmp_path / f"{k}.nc", 0.95)
        if all(v.outcome == "pass" for v in verdicts):
            costs[candidate] = sum(c.cost for c in candidate)
    best = min(costs.values())
    assert sum(c.cost for c in combo) == pytest.approx(best) and costs.get(combo) == pytest.approx(best)
    assert 1 <= sum(c.name == "H10/d10" for c in combo) <= 5          # a mixed answer: per joint pays off
    assert best < 6 * sum(c.cost for c in family)                   # below the per-family optimum


def test_greedy_per_joint_is_locally_least_cost(paper, joint_res):
    """Default fits (9^18 combinations: greedy): the answer passes, costs at most the per-family
    optimum, and no single joint moved to its next strictly cheaper class still passes."""
    specs, scene = [parse_spec(SPEC)], paper.scene()
    options = class_options(scene)
    found = joint_search(joint_res, options, specs, scene, 0.95)
    combo, judged, method, family = found.combo, found.judged, found.method, found.family_combo
    assert "greedy" in method and judged > 0
    assert all(np.all(s.holds(u)) for s, u in zip(specs, joint_uppers(joint_res, combo, specs, scene, 0.95)))
    assert sum(c.cost for c in combo) <= 6 * sum(c.cost for c in family) + 1e-9
    ranked = {f: sorted(options[f], key=lambda c: -c.cost) for f in ALLOCATED}
    for j, c in enumerate(combo):
        cheaper = [x for x in ranked[c.family] if x.cost < c.cost]
        if cheaper:
            looser = combo[:j] + (cheaper[0],) + combo[j + 1:]
            uppers = joint_uppers(joint_res, looser, specs, scene, 0.95)
            assert not all(np.all(s.holds(u)) for s, u in zip(specs, uppers)), joint_labels()[j]


def test_per_joint_command_writes_a_joint_table(configs, tmp_path, capsys):
    code = main(["allocate", str(configs / "paper.toml"), "--spec", SPEC, "-n", str(N), "--per-joint", "--classes",
                 "H8/f7,H10/d10", "-o", str(tmp_path / "a"), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["verification"] == "pass" and out["scene"] is None
    assert [c["joint"] for c in out["classes"]] == list(joint_labels())
    import xarray as xr

    from pipeline.files.schema import labelled
    with xr.open_dataset(tmp_path / "a" / "allocation.nc") as ds:
        ds = labelled(ds)
        assert list(ds["joint"].values) == list(joint_labels()) and ds["fit_class"].dims == ("joint",)
        assert list(ds["fit_class"].values) == [c["class"] for c in out["classes"]]
    assert out["total_cost"] == pytest.approx(sum(c["cost_per_joint"] for c in out["classes"]))


def test_a_per_joint_allocation_after_a_per_family_one_has_a_default_folder_of_its_own(configs, tmp_path,
                                                                                       monkeypatch, capsys):
    """The README's two allocate commands one after the other, without -o: the per-joint one was refused as
    another request in the per-family one's default folder; it now writes allocate_SCENE_MODEL_per-joint."""
    monkeypatch.chdir(tmp_path)
    argv = ["allocate", str(configs / "paper.toml"), "--spec", SPEC, "-n", str(N), "--classes", "H8/f7,H10/d10"]
    assert main(argv) == 0 and main(argv + ["--per-joint"]) == 0
    capsys.readouterr()
    assert (tmp_path / "allocate_paper_quasi-static" / "allocation.nc").is_file()
    assert (tmp_path / "allocate_paper_quasi-static_per-joint" / "allocation.nc").is_file()


@pytest.mark.parametrize("model", ["paper", "contact"])
def test_per_joint_is_refused_at_the_greedy_levels(configs, tmp_path, capsys, model):
    code = main(["allocate", str(configs / "paper.toml"), "--spec", SPEC, "--per-joint", "--model", model,
                 "-o", str(tmp_path / "a")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--per-joint" in err and "quasi-static" in err, err
    assert not (tmp_path / "a").exists()
