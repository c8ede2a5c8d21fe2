"""Training data of the PICNN: history maps (and, for scoring only, FEM phi maps) of the
training increments of one FEM run, with the pixel geometry recorded.

File layout (HDF5): datasets ``history`` and ``phase_field_gp``, shape (n, ny_px, nx_px),
N/mm^2 and 1; ``increment`` (n,), ``u`` (n,) mm; root attrs x0, y0, h_px, nx_px, ny_px, run.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ifenn import run_files
from ifenn.io import atomic_path, reading


def extract_training_data(fields_path: str | Path, increments: list[int], out_path: str | Path) -> None:
    """The training file: the pixel maps of ``increments`` of a FEM run's fields.h5, stacked."""
    states = run_files.read_states(fields_path, increments, keys=run_files.MAP_KEYS)
    attrs = run_files.fields_attrs(fields_path)
    with atomic_path(out_path) as tmp, h5py.File(tmp, "w") as out:
        out.attrs.update({k: attrs[k] for k in run_files.GRID_ATTRS})
        out.attrs["run"] = attrs["run"]
        for key in run_files.MAP_KEYS:
            out.create_dataset(key, data=np.stack([s[key] for s in states]), **run_files.COMPRESSION)
        out["increment"] = np.array(increments)
        out["u"] = np.array([s["u"] for s in states])


def read_training_data(path: str | Path) -> dict:
    with reading(path, "training data (.h5)"), h5py.File(path, "r") as h5:
        data = {key: h5[key][()] for key in h5}
        data.update({key: h5.attrs[key] for key in h5.attrs})
    return data
