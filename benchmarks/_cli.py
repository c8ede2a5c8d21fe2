"""What the benchmark scripts share: their common options, one thread, and where their IFENN
run specs come from (files given with --specs, else the config section's runs)."""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

from ifenn.config import REPO, ifenn_run_spec, load_config


def parser(doc: str, section: str, out: str, increments_help: str) -> argparse.ArgumentParser:
    """--config, --model, --specs (default: ``section``.runs of --config), --increments, --out, --devices."""
    cli = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    cli.add_argument("--config", nargs="+", default=[str(REPO / "config" / "config.yaml")])
    cli.add_argument("--model", default="results/picnn/model.pt")
    cli.add_argument("--specs", nargs="+", default=None,
                     help=f"IFENN run specs (results/ifenn/RUN/spec.json); default: {section}.runs of --config")
    cli.add_argument("--results", default="results", help="the workflow's results folder: meshes in mesh/, FEM runs in fem/")
    cli.add_argument("--increments", type=int, default=None, help=increments_help)
    cli.add_argument("--out", default=out)
    cli.add_argument("--devices", nargs="+", default=None, choices=["cpu", "cuda"],
                     help="where the network's methods run, side by side (default: cpu, and cuda where torch sees one)")
    return cli


def devices(args: argparse.Namespace):
    """The torch devices of --devices (None: ifenn.device.default_devices)."""
    from ifenn.device import resolve_device

    return None if args.devices is None else [resolve_device(d, "--devices") for d in args.devices]


def run_inputs(specs: list[dict], results: str | Path) -> dict[str, dict]:
    """Per run: its scene's mesh and its FEM run's directory, in the workflow's results layout."""
    results = Path(results)
    return {spec["name"]: {"mesh": results / "mesh" / f"{spec['scene_name']}.xdmf", "fem_dir": results / "fem" / spec["fem_run"]}
            for spec in specs}


def setup(args: argparse.Namespace, section: str) -> tuple[dict, list[dict]]:
    """One thread for torch, warnings only; (the config, the run specs to measure)."""
    logging.basicConfig(level=logging.WARNING)
    import torch

    torch.set_num_threads(1)
    config = load_config(*args.config)
    if args.specs:
        return config, [json.loads(Path(path).read_text()) for path in args.specs]
    return config, [ifenn_run_spec(config, run) for run in config[section]["runs"]]


#: a solver run's environment: one thread per process; Open MPI allowed as root (containers)
SOLVER_ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1"}


def run_fem_spec(spec: dict, mesh: Path, work: Path, ranks: int = 1):
    """The workflow's FEM solver (`python -m ifenn fem`) on ``spec`` in a process of its own (under
    ``mpirun`` for ranks > 1), its output in ``work / spec['name']``: the history (a DataFrame)."""
    import pandas as pd

    spec_path = work / f"{spec['name']}.json"
    spec_path.write_text(json.dumps(spec))
    out = work / spec["name"]
    command = [sys.executable, "-m", "ifenn", "fem", "--spec", str(spec_path), "--mesh", str(mesh), "--out", str(out), "--no-progress"]
    if ranks > 1:
        command = ["mpirun", "-n", str(ranks), "--oversubscribe", *command]
    subprocess.run(command, check=True, env=SOLVER_ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return pd.read_csv(out / "history.csv")

