"""Training data of the PICNN: history maps (and, for scoring only, FEM phi maps) of the
training increments of one FEM run, with the pixel geometry recorded.

File layout (HDF5): datasets ``history`` and ``phase_field_gp``, shape (n, ny_px, nx_px),
N/mm^2 and 1; ``increment`` (n,), ``u`` (n,) mm; root attrs x0, y0, h_px, nx_px, ny_px, run.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from .io import atomic_path

GEOMETRY = ("x0", "y0", "h_px", "nx_px", "ny_px")


def extract_training_data(fields_path: str | Path, increments: list[int], out_path: str | Path) -> None:
    with h5py.File(fields_path, "r") as fields:
        missing = [i for i in increments if f"increment_{i:06d}" not in fields]
        if missing:
            raise KeyError(f"{fields_path} has no fields for increments {missing}; saved: {sorted(fields)}")
        groups = [fields[f"increment_{i:06d}"] for i in increments]
        with atomic_path(out_path) as tmp, h5py.File(tmp, "w") as out:
            out.attrs.update({k: fields.attrs[k] for k in GEOMETRY})
            out.attrs["run"] = fields.attrs["run"]
            for key in ("history", "phase_field_gp"):
                out.create_dataset(key, data=np.stack([g[key][()] for g in groups]), compression="gzip")
            out["increment"] = np.array(increments)
            out["u"] = np.array([g.attrs["u"] for g in groups])


def read_training_data(path: str | Path) -> dict:
    with h5py.File(path, "r") as h5:
        data = {key: h5[key][()] for key in h5}
        data.update({key: h5.attrs[key] for key in h5.attrs})
    return data
