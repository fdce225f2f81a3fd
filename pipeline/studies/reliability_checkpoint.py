"""Resuming ``rss6 reliability``: OUT.checkpoint.nc holds every batch of evaluations so far.

Subset simulation and plain Monte Carlo draw every z from a fixed schedule of seeds, so a rerun asks
for the same batches in the same order. The checkpoint is rewritten (through a temporary file) after
each batch with all batches so far and the request that made them; a resumed run (``--resume``)
answers its first batches from it, after checking that each asks for the very z stored, and
computes only the rest: its result is that of an uninterrupted run. The checkpoint is removed once
the output is written.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from ..files.reading import load_netcdf
from ..files.writing import write_netcdf
from ..vocabulary import UserError

__all__ = ["Checkpoint", "CheckpointError", "checkpoint_path"]


class CheckpointError(UserError):
    """A checkpoint that cannot be resumed, or one left behind by a run not asked to resume."""


def checkpoint_path(output) -> Path:
    """Where the run writing ``output`` keeps its checkpoint."""
    output = Path(output)
    return output.with_name(output.name + ".checkpoint.nc")


class Checkpoint:
    """The batches (z, maxima) of the run ``request`` (a JSON-able dict naming everything that fixes
    its batches) at ``path``: read back when ``resume``; a checkpoint found without ``resume`` is
    refused (the run would silently start over and lose it)."""

    def __init__(self, path, request: dict, resume: bool):
        self.path, self.request = Path(path), json.dumps(request, sort_keys=True)
        self.batches, self.replayed = [], 0
        if self.path.exists() and not resume:
            raise CheckpointError(f"{self.path}: an interrupted run's checkpoint; rerun the same command with "
                                  "--resume to continue it, or remove it to start over")
        if self.path.exists():
            self.batches = self._read()

    def _read(self) -> list:
        ds = load_netcdf(self.path)
        if ds.attrs.get("request") != self.request:
            raise CheckpointError(f"{self.path}: made by a different request (scene, level, event, method, "
                                  "-n, --p0 or --seed); rerun that command with --resume, or remove it")
        batch = ds["batch"].values
        return [(ds["z"].values[batch == b], ds["maxima"].values[batch == b]) for b in range(int(batch.max()) + 1)]

    def evaluate(self, z: np.ndarray, compute) -> np.ndarray:
        """The maxima of batch z: stored ones while resuming, else ``compute(z)``, stored at once."""
        k = self.replayed
        if k < len(self.batches):
            stored_z, maxima = self.batches[k]
            if stored_z.shape != z.shape or not np.array_equal(stored_z, z):
                raise CheckpointError(f"{self.path}: batch {k} asks for other inputs than the checkpoint holds; "
                                      "remove it to start over")
            self.replayed += 1
            return maxima
        maxima = compute(z)
        self.batches.append((np.array(z), maxima))
        self.replayed += 1
        self._write()
        return maxima

    def _write(self) -> None:
        z = np.concatenate([b[0] for b in self.batches])
        maxima = np.concatenate([b[1] for b in self.batches])
        batch = np.concatenate([np.full(len(b[0]), k, np.int32) for k, b in enumerate(self.batches)])
        ds = xr.Dataset({"z": (("evaluation", "input"), z, {"units": "1"}),
                         "maxima": (("evaluation", "quantity", "direction"), maxima),
                         "batch": ("evaluation", batch, {"units": "1"})},
                        attrs={"title": "rss6 reliability checkpoint", "request": self.request})
        write_netcdf(ds, self.path)   # through a temporary file: a kill leaves the previous one

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)
