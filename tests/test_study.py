"""Speed/accuracy and stability studies: the commands on the smoke scene, and their pieces."""
import csv
import dataclasses

import numpy as np
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.studies.setting import TRADEOFF_STATISTICS, relative_errors
from pipeline.studies.tradeoff import pareto_front, recommend
from pipeline.files.reading import load_netcdf
from pipeline.vocabulary import DIRECTIONS, QUANTITIES
from rss6core.contact_dynamics import simulate_contact
from rss6core.clearance import draw_clearances

SMOKE = "smoke"                    # the shipped scene, by name


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def tradeoff_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("tradeoff")
    assert main(["tradeoff", SMOKE, "-n", "1", "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def stability_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    assert main(["stability", SMOKE, "-n", "1", "-o", str(out), "--horizon", "0.05"]) == 0
    return out


@pytest.mark.slow   # every level, integrator, step and mesh: 2-3 minutes on 2 shared cores
def test_tradeoff_writes_every_setting_with_finite_columns(tradeoff_dir, capsys):
    rows = _rows(tradeoff_dir / "tradeoff.csv")
    stats = [f"rel_err_{q}_{d}_{s}" for q in QUANTITIES for d in DIRECTIONS for s in TRADEOFF_STATISTICS]
    for col in ["model", "integrator", "dt_s", "elements_per_link", "modes",
                "seconds_per_realization"] + stats:
        assert col in rows[0], col
    assert {r["model"] for r in rows} >= {"quasi-static", "elastic", "paper", "contact"}
    for r in rows:
        assert all(np.isfinite(float(r[c])) for c in ["dt_s", "seconds_per_realization"] + stats)
        assert float(r["seconds_per_realization"]) > 0
    ds = load_netcdf(tradeoff_dir / "tradeoff.nc")  # the CF file mapped back to rss6's schema
    assert float(ds["reference_change"].max()) < 0.2             # halving its step changes little
    # each setting's stored error, recomputed with plain numpy from the stored statistics:
    # |s - ref| / max(|ref|, 0.1 % of the largest |ref| of its kind (translations, rotations))
    value = ds["statistic_value"].values
    ref = np.abs(ds["statistic_value"].sel(setting=ds.attrs["reference"]).values)
    floor = np.concatenate([np.repeat(1e-3 * ref[:, g].max(1, keepdims=True), 3, 1)
                            for g in (slice(0, 3), slice(3, 6))], 1)
    expected = np.abs(value - ref) / np.maximum(ref, floor)
    np.testing.assert_allclose(ds["relative_error"].values, expected, rtol=1e-12, atol=0)
    others = ds["setting"].values != ds.attrs["reference"]
    assert np.all(ds["max_relative_error"].values[others] > 0)   # other settings do differ
    # the Craig-Bampton rows, each against its full-mesh twin (the same label without the modes)
    labels = list(ds["setting"].values)
    reduced = [i for i, m in enumerate(ds["link_modes"].values) if m > 0]
    assert {rows[i]["model"] for i in reduced} == {"elastic", "paper", "contact"}
    for i in reduced:
        twin = labels.index(labels[i].replace(f", Craig-Bampton {int(ds['link_modes'].values[i])} modes", ""))
        expected = relative_errors(value[i], value[twin])
        np.testing.assert_allclose(ds["relative_error_full_mesh"].values[i], expected, rtol=1e-12, atol=0)
        assert float(rows[i]["max_rel_error_vs_full_mesh"]) == pytest.approx(expected.max(), rel=1e-5)
        assert int(rows[i]["modes"]) < int(rows[twin]["modes"])
    full_mesh = [i for i in range(len(labels)) if i not in reduced]
    assert np.isnan(ds["max_relative_error_full_mesh"].values[full_mesh]).all()
    assert (tradeoff_dir / "tradeoff.png").stat().st_size > 10_000


def test_stability_map_and_the_explicit_limit(stability_dir):
    rows = _rows(stability_dir / "stability.csv")
    for col in ("level", "integrator", "dt_s", "status", "max_rel_change", "seconds_per_realization"):
        assert col in rows[0]
    assert {r["status"] for r in rows} <= {"stable", "inaccurate", "failed"}
    assert all(np.isfinite(float(r[c])) for r in rows for c in ("dt_s", "max_rel_change",
                                                                 "seconds_per_realization"))
    from pipeline.scenes.catalogue import find_scene
    from pipeline.studies.stability import STABILITY_LINK_MODES
    from rss6core.models import natural_frequencies
    full = find_scene(SMOKE)
    reduced = dataclasses.replace(full, beam=dataclasses.replace(full.beam, link_modes=STABILITY_LINK_MODES))
    for scene, name in ((full, "central-difference (undamped)"),
                        (reduced, f"central-difference (undamped), Craig-Bampton {STABILITY_LINK_MODES} modes")):
        explicit = [r for r in rows if r["integrator"] == name]
        limit = 2.0 / natural_frequencies(scene)[-1]
        assert len(explicit) == 7
        for r in explicit:      # stable below 2/omega_max, diverging above it (within 3 %)
            h = float(r["dt_s"])
            if h < 0.97 * limit:
                assert r["status"] != "failed", r
            if h > 1.03 * limit:
                assert r["status"] == "failed", r
    for r in rows:          # the implicit elastic methods are unconditionally stable
        if r["level"] == "elastic" and not r["integrator"].startswith("central"):
            assert r["status"] != "failed", r
    paper = sorted((r for r in rows if r["level"] == "paper"), key=lambda r: float(r["dt_s"]))
    v = [float(r["velocity_mean_peak_m_s"]) for r in paper]
    assert all(a > b for a, b in zip(v, v[1:]))  # the paper level's error grows as the step shrinks
    assert (stability_dir / "stability.png").stat().st_size > 10_000


def _sweep_runs(changes: dict) -> dict:
    """Made-up measured runs {step: run} whose statistics differ from the finest step's by ``changes[step]``."""
    base = np.ones((3, 6, 2))
    return {h: {"statistics": base * (1 + c), "failed": 0, "message": "", "seconds_per_realization": 0.1}
            for h, c in changes.items()}


def test_the_summary_names_the_reference_and_no_accurate_step_it_cannot_show(smoke):
    """Review 63: the finest step (the reference) was called 'largest accurate' when no coarser step was
    within the tolerance, and at the paper level, whose velocity and acceleration errors measure the step;
    the log rows read 'stable ' and 'inaccurateSTATISTICS...' without a separator."""
    from pipeline.studies.stability import _rows, _stability_dataset, summary_lines
    from pipeline.vocabulary import STEP_WORDS
    log = []
    rows = []
    for level, changes in (("elastic", {1e-3: 0.0, 2e-3: 0.01, 4e-3: 0.2}), ("contact", {5e-5: 0.0, 1e-4: 1.2}),
                           ("paper", {2.5e-4: 0.0, 5e-4: 0.01})):   # a paper row within 5 %: still not accurate
        rows += _rows(_sweep_runs(changes), level, "newmark", 1.0, 0.2, 0.05, log.append, lambda h: f"dt {h:g} s")
    assert log[0] == "  elastic newmark dt 0.001 s: reference (the finest step, which the others are compared with)"
    assert log[1] == "  elastic newmark dt 0.002 s: stable"
    assert log[2] == "  elastic newmark dt 0.004 s: inaccurate: statistics change 20.0 % vs the finest step"
    elastic, contact, paper = summary_lines(_stability_dataset(rows, 1e-4, 0.05, 1, 0, smoke))
    assert elastic.startswith("elastic newmark: reference 0.001 s, ") and elastic.endswith(
        "largest step within 5 % of the reference's statistics 0.002 s"), elastic
    assert contact.endswith("none coarser than the reference is within 5 %"), contact
    assert "accurate" not in contact and "0.0001 s" not in contact.split("smallest failed")[1], contact
    assert f"no step named accurate: its velocity and acceleration errors {STEP_WORDS}" in paper, paper
    assert "0.0005" not in paper.split("smallest failed")[1], paper


def test_pareto_front_keeps_only_undominated_settings():
    cost = np.array([1.0, 2.0, 3.0, 4.0, 0.5])
    error = np.array([0.5, 0.6, 0.1, 0.05, 0.9])
    assert pareto_front(cost, error).tolist() == [4, 0, 2, 3]
    # a setting with failed realisations (the cheapest, or the most accurate) is on no front
    assert pareto_front(cost, error, [False, True, True, True, True]).tolist() == [4, 1, 2, 3]
    assert pareto_front(cost, error, [True, True, True, False, True]).tolist() == [4, 0, 2]


def test_relative_error_floor_and_recommendation():
    ref = np.zeros((3, 6, 2))
    ref[:, :3] = 1.0
    ref[:, 2] = 1e-9                 # a vanishing component is measured against 0.1 % of the largest
    stats = ref + 1e-6
    rel = relative_errors(stats, ref)
    assert rel[:, 0].max() == pytest.approx(1e-6)
    assert rel[:, 2].max() == pytest.approx(1e-6 / 1e-3)
    ds = xr.Dataset({"seconds_per_realization": ("setting", [10.0, 1.0, 2.0, 0.5]),
                     "max_relative_error": ("setting", [0.0, 0.04, 0.01, 0.2]),
                     "failed": ("setting", [0, 0, 0, 0])},
                    coords={"setting": ["ref", "a", "b", "c"]}, attrs={"reference": "ref"})
    rec = recommend(ds, 0.05)
    assert rec["setting"] == "a" and rec["speedup_vs_reference"] == pytest.approx(10.0)
    assert recommend(ds, 0.001)["setting"] is None


def test_settle_time_leaves_the_start_up_out_of_the_peaks(smoke):
    scene = dataclasses.replace(smoke, trajectory=dataclasses.replace(smoke.trajectory, duration=0.06))
    draws = [draw_clearances(scene, 0, 0)]
    full = simulate_contact(scene, draws)
    late = simulate_contact(scene, draws, settle=0.03)
    assert np.array_equal(full.displacement, late.displacement)   # the motion is the same
    after = late.t >= 0.03
    late_peak, full_peak = late.peak.max(1), full.peak.max(1)   # over the startup and steady windows
    for q, hist in enumerate((late.displacement, late.velocity, late.acceleration)):
        sampled = np.abs(hist[0, after]).max(0)
        assert np.all(late_peak[0, q] >= sampled)               # every internal step counts ...
        assert np.all(late_peak[0, q] <= full_peak[0, q])       # ... but none before the settle time
    assert np.any(late_peak[0, 2] < full_peak[0, 2])            # the start-up impacts are left out


def test_a_setting_names_integrator_and_mesh_only_for_the_levels_that_integrate_the_links():
    """The level table's elastic_links decides the label's form (rigid and quasi-static integrate nothing)."""
    from pipeline.studies.setting import Setting
    assert Setting("rigid", "hht", 1e-3, 4).label == "rigid 1 ms"
    assert Setting("quasi-static", "hht", 2e-3, 4).label == "quasi-static 2 ms"
    assert Setting("elastic", "hht", 1e-3, 4).label == "elastic hht 1 ms 4 el"
    assert Setting("paper", "newmark", 5e-4, 8).label == "paper newmark 0.5 ms 8 el"
    assert Setting("contact", "hht", 1e-4, 2, 10.0).label == "contact hht 0.1 ms 2 el, K x10"


def test_no_timed_setting_pays_the_compiled_kernels_load(smoke, monkeypatch):
    """The first contact setting of a tradeoff once carried numba's compile in its cost (31 s against 0.13 s
    per realisation on the rerun): one untimed realisation of the cheapest contact setting now comes first,
    and its time is nobody's cost."""
    import pipeline.studies.setting as setting_module
    import pipeline.studies.tradeoff as tradeoff_module
    from pipeline.studies.setting import Setting
    calls = []

    def recorded(scene, setting, n, seed=0):
        calls.append((setting, n))
        return {"seconds_per_realization": 1.0 + len(calls), "statistics": np.ones((3, 6, len(TRADEOFF_STATISTICS))),
                "failed": 0, "message": ""}

    monkeypatch.setattr(setting_module, "measure", recorded)
    monkeypatch.setattr(tradeoff_module, "measure", recorded)
    paper = Setting("paper", "newmark", 1e-3, 2)
    contact = [Setting("contact", "generalized-alpha", h, 2) for h in (1e-4, 2e-4)]
    ds = tradeoff_module.tradeoff(smoke, 3, settings=[paper, *contact], reference=contact[0], log=lambda *_: None)
    assert calls[0] == (contact[1], 1)   # the largest contact step, one realisation, before any timed run
    assert all(n == 3 for _, n in calls[1:])
    assert sorted(ds["seconds_per_realization"].values) == [3.0, 4.0, 5.0]   # calls 2-4; the warm-up's 2.0 unused
