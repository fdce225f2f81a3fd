"""The finished chunks of ``rss6 sensitivity`` kept in OUT.parts: each design's rows, stored as soon as a
chunk finishes, with the manifest (checksum, rows, provenance) that a rerun resumes from."""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import xarray as xr

from rss6core import __version__

from ..files.outputs import PartsManifest
from ..files.reading import load_netcdf
from ..files.schema import MIXED_UNITS, _unit_table, settings_attrs
from ..vocabulary import DIRECTIONS, QUANTITIES, SUMMARIES, UserError

__all__ = ["PART_SETTINGS", "parts_manifest", "RowParts"]


PART_SETTINGS = "scene, model, integrator, step, mesh, seed, -n, --per-joint or --window"


def parts_manifest(spec, n: int, per_joint: bool, window: str, folder) -> PartsManifest:
    """The manifest of ``folder`` (OUT.parts), whose provenance names all the stored rows depend on;
    EnsembleFileError (before any work) for parts of other settings or changed since written."""
    provenance = {"scene_toml": spec.scene_text, **settings_attrs(model=spec.model, integrator=spec.integrator,
                                                                   dt=float(spec.dt), elements=int(spec.elements)),
                  "seed": int(spec.seed), "n_base_samples": n, "per_joint": per_joint, "window": window,
                  "designs": ["families"] + (["joints"] if per_joint else []), "rss6_version": __version__}
    manifest = PartsManifest(folder, provenance, index="row", items="rows", settings=PART_SETTINGS)
    manifest.checked_parts(lambda path, verify: _chunk(path, verify, provenance))
    return manifest


def _provenance_text(provenance: dict) -> str:
    """The manifest's provenance as each stored chunk carries it (its ``provenance`` attribute)."""
    return json.dumps(provenance, sort_keys=True)


def _chunk(path, verify: bool, provenance: dict) -> xr.Dataset:
    """Stored chunk ``path`` if it was made with the run's ``provenance``; UserError otherwise."""
    ds = load_netcdf(path, verify=verify)
    if ds.attrs.get("provenance") != _provenance_text(provenance):
        raise UserError(f"{path}: made with other settings ({PART_SETTINGS})")
    return ds


@dataclass(frozen=True)
class RowParts:
    """The stored chunks of one design: ``DESIGN-FIRST-LAST.nc`` in the manifest's folder, holding
    the statistics (rows, 2, 3, 6) SI of the design's rows FIRST..LAST."""
    manifest: PartsManifest
    design: str

    def parts(self) -> list:
        """The design's stored chunks (verified by :func:`parts_manifest`)."""
        return [path for path in self.manifest.parts() if path.name.startswith(f"{self.design}-")]

    def stored(self) -> list[tuple[slice, np.ndarray]]:
        """(rows, their statistics) of every stored chunk of the design."""
        return [(slice(int(ds["row"][0]), int(ds["row"][-1]) + 1), np.stack([ds[k].values for k in SUMMARIES], axis=1))
                for ds in (load_netcdf(path, verify=False) for path in self.parts())]

    def count(self) -> int:
        """How many of the design's rows are stored (as the manifest lists them, without reading the chunks)."""
        return sum(len(self.manifest.entries[path.name]["rows"]) for path in self.parts())

    def keep(self, rows: slice, stats: np.ndarray) -> None:
        """Store the statistics of ``rows`` at once (PartsManifest.write: all or nothing)."""
        self.manifest.write(_part_dataset(self.design, rows, stats, self.manifest.provenance),
                            f"{self.design}-{rows.start:07d}-{rows.stop - 1:07d}.nc")


def _part_dataset(design: str, rows: slice, stats: np.ndarray, provenance: dict) -> xr.Dataset:
    """A stored chunk: the statistics (rows, 2, 3, 6) SI of ``rows`` of the ``design``'s sample, with the
    run's ``provenance`` (which a lost manifest's chunks are adopted by)."""
    data = {name: (("row", "quantity", "direction"), stats[:, s], {"long_name": f"{what} over time of |platform "
                                                                   "pose error| of the row", "units": MIXED_UNITS})
            for s, (name, what) in enumerate(zip(SUMMARIES, ("maximum", "mean")))}
    coords = {"row": ("row", np.arange(rows.start, rows.stop), {"long_name": f"row of the {design} design's sample"}),
              "quantity": ("quantity", list(QUANTITIES)), "direction": ("direction", list(DIRECTIONS)),
              "unit": (("quantity", "direction"), _unit_table(), {"long_name": "SI unit of the statistic"})}
    return xr.Dataset(data, coords=coords, attrs={"title": f"rss6 sensitivity: finished rows of the {design} design",
                                                  "design": design, "provenance": _provenance_text(provenance)})
