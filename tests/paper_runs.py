"""The paper's runs as they were: the quick DAG's histories of the FEM, published IFENN, verified,
whole-path and adaptive runs, kept in tests/data/paper_runs/ so that a change which should move no
number is checked against them (tests/test_paper_runs.py).

Refresh them only when a change is meant to move these numbers, and say so in its commit:

    .venv/bin/python tests/paper_runs.py RESULTS_DIR     # RESULTS_DIR: a quick DAG's results/
"""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

import pandas as pd

REFERENCES = Path(__file__).resolve().parent / "data" / "paper_runs"

#: (kind, run): the runs whose histories must not move; one of each method, on a slit scene, a
#: two-notch scene, a cut-out and a beam
RUNS = (
    ("fem", "snt1-I"), ("fem", "sdnt"), ("fem", "l-panel"), ("fem", "three-point-bending"), ("fem", "snt1-A-conv"),
    ("ifenn", "snt1-I"), ("ifenn", "adnt"), ("ifenn", "snt1-I-pz"),
    ("ifenn", "snt1-I-verified"), ("ifenn", "sdnt-verified"), ("ifenn", "l-panel-verified"), ("ifenn", "snt1-II-verified-nonet"),
    ("ifenn", "snt1-I-whole"), ("ifenn", "l-panel-whole"),
    ("adaptive", "snt1-II-adaptive"), ("adaptive", "snt1-II-adaptive-verified"), ("adaptive", "l-panel-adaptive-verified"),
    ("adaptive", "snt1-A-conv-adaptive"),
)


def compared_columns(history: pd.DataFrame) -> list[str]:
    """Every column but the timings (``t_*``, ``*_s``): what the run computed, not how long it took."""
    return [c for c in history.columns if not (c.startswith("t_") or c.endswith("_s"))]


def read(path) -> pd.DataFrame:
    """A history as written, to the last bit (pandas' default float parser may miss by an ulp)."""
    return pd.read_csv(path, float_precision="round_trip")


def machine() -> dict:
    """The processor the references were computed on (BLAS kernels, and so round-off, follow it)."""
    model = ""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        model = next((line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines() if line.startswith("model name")), "")
    return {"processor": model or platform.processor(), "machine": platform.machine()}


def refresh(results: Path) -> None:
    for kind, run in RUNS:
        history = read(results / kind / run / "history.csv")
        target = REFERENCES / kind / f"{run}.csv"
        target.parent.mkdir(parents=True, exist_ok=True)
        history[compared_columns(history)].to_csv(target, index=False)
    (REFERENCES / "machine.json").write_text(json.dumps(machine(), indent=1) + "\n")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    refresh(Path(sys.argv[1]))
