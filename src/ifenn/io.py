"""Files: atomic writes, provenance records, the log of a workflow step, progress bars."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import pickle
import platform
import sys
import time
import zipfile
import zlib
from pathlib import Path


class CorruptFileError(RuntimeError):
    """A file that exists but cannot be read: truncated, or overwritten in part."""


#: what the readers of the package's files raise on a damaged file (h5py: OSError; torch and
#: dolfinx: RuntimeError; numpy's .npz: zipfile.BadZipFile, EOFError, ValueError or zlib.error)
_READ_ERRORS = (OSError, RuntimeError, EOFError, ValueError, zipfile.BadZipFile, zlib.error, pickle.UnpicklingError)

#: how to get a file back that a workflow rule writes
REBUILD = "delete it and rerun the workflow (Snakemake rebuilds a missing file)"


@contextlib.contextmanager
def reading(path: str | Path, what: str, rebuild: str = REBUILD):
    """Read ``path`` inside this block: a damaged file ends in one line that names it, says
    what it is and how to get it back, instead of the reading library's traceback."""
    try:
        yield
    except CorruptFileError:
        raise
    except _READ_ERRORS as error:
        if isinstance(error, FileNotFoundError):
            raise
        reason = (str(error).strip().splitlines() or [type(error).__name__])[0]
        raise CorruptFileError(f"{path}: cannot read this {what}, it is damaged or truncated ({reason}); {rebuild}") from None


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block
    finishes, so a half-written file never looks finished."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".tmp-{os.getpid()}-{path.name}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_json(path: str | Path, data: dict) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(data, indent=1, sort_keys=True, default=str))


def write_csv(path: str | Path, frame) -> None:
    """Write a pandas DataFrame atomically (no index column)."""
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False)


def software_versions() -> dict:
    versions = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("numpy", "dolfinx", "petsc4py", "torch", "snakemake", "meshio"):
        module = sys.modules.get(name)
        if module is not None:
            versions[name] = getattr(module, "__version__", "?")
    return versions


def provenance(spec_hash: str, wall_s: float, **extra) -> dict:
    """A small record written beside every result: what, with what, how long."""
    return {"spec_hash": spec_hash, "wall_time_s": round(wall_s, 3), "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "versions": software_versions(), **extra}


def log_to(path: str | Path):
    """Send this process's logging (INFO and up) and its stderr (warnings, tracebacks, progress
    bars) to ``path``, line-buffered: the ``log:`` file of a Snakemake rule. Returns the stream."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stream = open(path, "w", buffering=1)  # noqa: SIM115 (open for the rest of the process)
    sys.stderr = stream
    logging.basicConfig(stream=stream, level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s", force=True)
    return stream


class _NoBar:
    """What a disabled bar does: nothing (and it needs no tqdm)."""

    def update(self, n=1):
        pass

    def set_postfix(self, *args, **kwargs):
        pass

    def close(self):
        pass


def progress_bar(**options):
    """A tqdm bar that refreshes twice a second on a terminal and every 30 s into a file (a
    rule's log), so a log holds a few lines per minute, not one per update. A disabled bar
    (``disable=True``) does not import tqdm: the GPU benchmark runs where it is not installed."""
    if options.get("disable"):
        return _NoBar()
    from tqdm import tqdm

    interactive = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(mininterval=0.5 if interactive else 30.0, **options)
