"""The files of a run directory: each format is written and read here, and nowhere else.

    spec.json        the run's resolved description (:func:`ifenn.config.fem_run_spec`,
                     :func:`~ifenn.config.ifenn_run_spec`): every option the run used
    history.csv      one row per increment (:data:`ifenn.fem.solver.HISTORY_COLUMNS` and the
                     phase-field step's own columns)
    fields.h5        per saved increment a group ``increment_NNNNNN`` (attrs ``u``,
                     ``increment``) holding the pixel maps ``history`` and ``phase_field_gp``
                     (ny_px, nx_px), the nodal ``phase_field`` (n_nodes,) and ``displacement``
                     (n_nodes, 2) in mesh-file order; root attrs: the pixel grid (``x0``, ``y0``,
                     ``h_px``, ``nx_px``, ``ny_px``), ``run``, ``spec_hash`` and
                     ``switch_increment`` (-1: the phi threshold was never reached)
    provenance.json  spec hash, software versions, wall time, and what the run adds
    status.json      a stability cell's outcome: ``status`` (ok / failed), ``error``, ``wall_s``
    .work/           a run in progress: checkpoint.npz (the state to resume from), the saved
                     increments fields_NNNNNN.npz, and the lock of the process writing the run

Every write is atomic (:func:`ifenn.io.atomic_path`): a file that exists is complete.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import socket
import time
from collections.abc import Iterable
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from ifenn.io import atomic_path, reading, write_csv, write_json


def spec_hash(spec: dict) -> str:
    """Stable short hash of a spec (canonical JSON), recorded in provenance and checkpoints."""
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]

SPEC, HISTORY, FIELDS, PROVENANCE, STATUS = "spec.json", "history.csv", "fields.h5", "provenance.json", "status.json"
#: the datasets of a saved increment; the first two are the pixel maps
FIELD_KEYS = ("history", "phase_field_gp", "phase_field", "displacement")
MAP_KEYS = FIELD_KEYS[:2]
#: written where a state has them (ifenn.adaptive): the leaf level of each fine cell of an adaptive
#: mesh, and the pixels of the fine regions a run continues from (``region``: the last increment's,
#: ``mesh_region``: the one the mesh was built from)
OPTIONAL_KEYS = ("leaf_level", "region", "mesh_region")
#: the pixel grid's root attributes
GRID_ATTRS = ("x0", "y0", "h_px", "nx_px", "ny_px")


#: what a damaged fields.h5 is called in the error
_FIELDS_WHAT = "run's saved fields (fields.h5)"


@contextlib.contextmanager
def _open_fields(path: str | Path):
    """A fields.h5 open for reading; a damaged one raises one line naming it (ifenn.io.reading)."""
    with reading(path, _FIELDS_WHAT), h5py.File(path, "r") as h5:
        yield h5


def _group(increment: int) -> str:
    return f"increment_{int(increment):06d}"


def _increment(group: str) -> int:
    return int(group.split("_")[1])


# --------------------------------------------------------------------------- fields.h5
#: lossless; byte shuffle + gzip level 1 against gzip level 4 alone (sdnt-adaptive's 32 states,
#: 246 MB raw): written in 2.9 s against 4.5 s, 157 MB against 183, read in 1.1 s against 1.3
COMPRESSION = {"compression": "gzip", "compression_opts": 1, "shuffle": True}

def write_fields(path: str | Path, attrs: dict, states: Iterable[dict]) -> None:
    """fields.h5 from root ``attrs`` and ``states`` (dicts with ``increment``, ``u`` and the
    FIELD_KEYS arrays; a nodal phase field of shape (n, 1) is stored as (n,))."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs.update(attrs)
        for state in states:
            group = h5.create_group(_group(state["increment"]))
            group.attrs.update({"u": float(state["u"]), "increment": int(state["increment"])})
            for key in FIELD_KEYS + tuple(k for k in OPTIONAL_KEYS if k in state):
                values = np.asarray(state[key])
                group.create_dataset(key, data=values[:, 0] if key == "phase_field" and values.ndim == 2 else values,
                                     **COMPRESSION)


def fields_attrs(path: str | Path) -> dict:
    """The root attributes of a fields.h5."""
    with _open_fields(path) as h5:
        return dict(h5.attrs)


def saved_increments(path: str | Path) -> list[int]:
    """The increments a fields.h5 holds, ascending."""
    with _open_fields(path) as h5:
        return sorted(_increment(g) for g in h5)


def read_states(path: str | Path, increments: Iterable[int] | None = None, keys: Iterable[str] = FIELD_KEYS,
                after: int | None = None) -> list[dict]:
    """Saved states of a fields.h5, ascending: dicts with ``increment``, ``u`` and ``keys``.
    ``increments``: exactly these (KeyError naming the saved ones if one is missing); else all,
    or those after ``after``."""
    keys = tuple(keys)
    with _open_fields(path) as h5:
        saved = sorted(_increment(g) for g in h5)
        if increments is not None:
            wanted = [int(i) for i in increments]
            missing = [i for i in wanted if i not in saved]
            if missing:
                raise KeyError(f"{path} has no fields for increments {missing}; saved: {saved}")
        else:
            wanted = [i for i in saved if after is None or i > after]
        states = []
        for increment in wanted:
            group = h5[_group(increment)]
            states.append({"increment": increment, "u": float(group.attrs["u"]), **{key: group[key][()] for key in keys}})
        return states


def read_phase_field_maps(path: str | Path) -> tuple[dict, dict]:
    """{increment: (u, phase_field_gp map)} and the root attrs of a fields.h5."""
    maps = {s["increment"]: (s["u"], s["phase_field_gp"]) for s in read_states(path, keys=("phase_field_gp",))}
    return maps, fields_attrs(path)


# --------------------------------------------------------------------------- .work/*.npz
def write_state(path: str | Path, state: dict) -> None:
    """A checkpoint or a saved increment of a run in progress (numbers only, .npz)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        np.savez(stream, **state)


def read_state(path: str | Path) -> dict:
    """All arrays of a file of :func:`write_state`; a damaged one raises one line naming it."""
    rebuild = "delete it: the run then starts again from its first increment (or its switch-over)"
    with reading(path, "run state of a run in progress (.npz)", rebuild), np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


# --------------------------------------------------------------------------- .work/lock
WORK, LOCK = ".work", "lock"


class RunInProgressError(RuntimeError):
    """Another process is writing the run directory."""


@contextlib.contextmanager
def exclusive_writer(run_dir: str | Path, comm=None):
    """Hold the run directory for this process while the block runs; a second process on the
    same run refuses at once, naming the holder. The lock is ``flock`` on ``.work/lock``: the
    operating system releases it when its holder exits or is killed (kill -9 included), so a
    dead run never blocks its rerun, and a live one (an orphan of a killed job shell) is never
    raced by it. With MPI, rank 0 holds it for all ranks."""
    work = Path(run_dir) / WORK
    rank0 = comm is None or comm.rank == 0
    stream, refusal = None, None
    if rank0:
        work.mkdir(parents=True, exist_ok=True)
        stream = open(work / LOCK, "a+")  # noqa: SIM115 (held for the block)
        try:
            fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            stream.seek(0)
            holder = stream.read().strip() or "another process"
            stream.close()
            stream = None
            refusal = (f"run directory {run_dir} is being written by {holder}: wait for it to finish, or stop that "
                       "process and rerun (the run resumes from its checkpoint)")
        else:
            stream.seek(0)
            stream.truncate()
            stream.write(f"pid {os.getpid()} on {socket.gethostname()} since {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            stream.flush()
    if comm is not None:
        refusal = comm.bcast(refusal, root=0)
    if refusal:
        raise RunInProgressError(refusal)
    try:
        yield
    finally:
        if stream is not None:
            stream.close()


# --------------------------------------------------------------------------- the others
def read_history(run_dir: str | Path) -> pd.DataFrame:
    return pd.read_csv(Path(run_dir) / HISTORY)


def write_history(run_dir: str | Path, frame: pd.DataFrame) -> None:
    write_csv(Path(run_dir) / HISTORY, frame)


def read_spec(path: str | Path) -> dict:
    """A spec.json: the file itself, or the run directory that holds it."""
    path = Path(path)
    return json.loads((path / SPEC if path.is_dir() else path).read_text())


def write_spec(path: str | Path, spec: dict) -> None:
    write_json(path, spec)


def read_status(run_dir: str | Path) -> dict:
    return json.loads((Path(run_dir) / STATUS).read_text())


def write_status(run_dir: str | Path, status: dict) -> None:
    write_json(Path(run_dir) / STATUS, status)


def read_provenance(run_dir: str | Path) -> dict:
    return json.loads((Path(run_dir) / PROVENANCE).read_text())


def take_over(start: dict, start_dir: str | Path, work_dir: str | Path, save: Iterable[int],
              keys: Iterable[str] = FIELD_KEYS) -> tuple[dict, list[dict]]:
    """The start of a run whose first increments another run computed (a spec's ``start_from``:
    {'run', 'increment' k, 'spec_hash'}; :func:`ifenn.config.shared_prefix`): the other run's saved
    state at k (``keys``) and its history rows 1..k, read from ``start_dir``. Its saved increments
    up to k among ``save`` and its switch-over increment are copied into ``work_dir`` as this run's
    own (fields.h5 then holds them as if computed here). Raises, naming the run to rerun, when
    ``start_dir`` holds another spec's outputs or lacks one of those increments."""
    fields, k = Path(start_dir) / FIELDS, int(start["increment"])
    attrs = fields_attrs(fields)
    if str(attrs.get("spec_hash")) != start["spec_hash"]:
        raise ValueError(f"{fields} is not run {start['run']} of spec hash {start['spec_hash']} (it has {attrs.get('spec_hash')}): "
                         f"rerun {start['run']} first")
    switch = int(attrs.get("switch_increment", -1))
    copied = {i for i in save if i <= k} | ({switch} if 0 < switch <= k else set())
    try:
        states = read_states(fields, sorted(copied | {k}), keys=keys)
    except KeyError as error:
        raise KeyError(f"run {start['run']} did not save what this run starts from ({error}): rerun {start['run']}") from None
    Path(work_dir).mkdir(parents=True, exist_ok=True)
    for state in states:
        path = Path(work_dir) / f"fields_{state['increment']:06d}.npz"
        if state["increment"] in copied and not path.exists():
            write_state(path, state)
    history = read_history(start_dir)
    return states[-1], history[history.increment <= k].to_dict("records")


def read_run_wall(run_dir: str | Path) -> float:
    """The whole run's wall time: provenance.json's ``wall_time_s`` plus ``start_wall_s``, the
    increments it took over from the run it started from (:func:`ifenn.config.shared_prefix`)."""
    record = read_provenance(run_dir)
    return float(record["wall_time_s"]) + float(record.get("start_wall_s") or 0.0)


def write_provenance(run_dir: str | Path, record: dict) -> None:
    write_json(Path(run_dir) / PROVENANCE, record)
