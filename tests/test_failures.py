"""One realisation's failure fails that realisation only: the rest of its chunk is kept, and the
file is the same whatever the chunk size and the worker count, failures included."""
import numpy as np
import xarray as xr

import pipeline.ensemble.run as run
from rss6core import Level
from pipeline.ensemble.run import EnsembleSpec, run_chunk, run_ensemble
from pipeline.scenes.variant import scene_variant
from pipeline.scenes.catalogue import scene_text
from pipeline.files.records import finish_ensemble

SMOKE_TEXT = scene_text("smoke")
PER_REALISATION = ["status", "status_message", "max_abs_error", "mean_abs_error", "eccentricity"]


def _quasi_static(seed=3):
    return EnsembleSpec(SMOKE_TEXT, "smoke", "quasi-static", "newmark", 1e-3, 4, seed)


def test_a_realisation_that_raises_fails_alone_and_its_chunk_keeps_the_others(monkeypatch):
    """Realisation 2 raises (a stand-in for a numerical failure of the batch) whenever it is
    simulated: it alone is recorded as failed, with the reason and its draw; the other three are
    exactly what a clean run gives; the chunk equals the same realisations run one per chunk."""
    spec = _quasi_static()
    clean = run_chunk(spec, [0, 1, 2, 3])
    simulate = Level.simulate

    def fails_with_2(level, seed, realizations, uniforms=None):
        if 2 in realizations:
            raise FloatingPointError("overflow in the closure of realisation 2")
        return simulate(level, seed, realizations, uniforms)

    monkeypatch.setattr(Level, "simulate", fails_with_2)
    chunk = run_chunk(spec, [0, 1, 2, 3])
    assert list(chunk["status"].values) == ["finished", "finished", "failed", "finished"]
    assert chunk["status_message"].values[2] == "FloatingPointError: overflow in the closure of realisation 2"
    assert np.isnan(chunk["max_abs_error"].sel(realization=2)).all()
    kept = [0, 1, 3]
    xr.testing.assert_equal(chunk[PER_REALISATION].sel(realization=kept),     # values, not n_failed
                            clean[PER_REALISATION].sel(realization=kept))
    xr.testing.assert_identical(chunk["eccentricity"], clean["eccentricity"])
    singles = finish_ensemble([run_chunk(spec, [r]) for r in range(4)], spec.scene(), **run._kw(spec))
    xr.testing.assert_identical(singles, chunk)
    assert chunk.attrs["n_failed"] == 1


# The contact level at a 0.5 ms step on the first 15 ms of the smoke scene: Newton fails in the
# start-up impacts of 7 of these 12 draws (at t = 11-14 ms) and converges in the other 5.
CONTACT_FAILING = EnsembleSpec(scene_variant(SMOKE_TEXT, {"trajectory": {"duration_s": 0.015}}, "smoke"),
                               "smoke", "contact", "generalized-alpha", 5e-4, 4, 0)


def test_failures_leave_the_file_the_same_for_any_chunk_size_and_worker_count(tmp_path, cluster_client):
    """12 realisations, some failing, as one chunk on 1 worker, and in chunks of 1 and of 3 on 2
    workers: the three files are byte for byte the same."""
    whole = tmp_path / "all-1worker.nc"
    ds = run_ensemble(CONTACT_FAILING, 12, whole, workers=1, chunk=12, progress=False)
    status = list(ds["status"].values)
    assert 3 <= status.count("failed") <= 9, status
    assert all("Newton on the contact forces did not converge" in m
               for m, s in zip(ds["status_message"].values, status) if s == "failed")
    for chunk in (1, 3):
        path = tmp_path / f"chunk{chunk}-2workers.nc"
        run_ensemble(CONTACT_FAILING, 12, path, workers=2, chunk=chunk, progress=False,
                     client=cluster_client)
        assert path.read_bytes() == whole.read_bytes(), f"chunks of {chunk} differ"

