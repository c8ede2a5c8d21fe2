"""The phase-field step, FEM against IFENN with full-image, process-zone and verified inference,
on snt1/snt2/snt3 (config 'phase_field_benchmark'): same process, same core, same loads from
each FEM run's switch-over state (see ifenn.benchmark). Needs the FEM runs and the trained
PICNN of the workflow (results/). Run it alone: the numbers are wall times.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/phase_field_speed.py [--increments N] [--out CSV]
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import pandas as pd

from ifenn.benchmark import phase_field_speed
from ifenn.config import REPO, ifenn_run_spec, load_config


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", nargs="+", default=[str(REPO / "config" / "config.yaml")])
    parser.add_argument("--model", default="results/picnn/model.pt")
    parser.add_argument("--specs", nargs="+", default=None,
                        help="IFENN run specs (results/ifenn/RUN/spec.json); default: phase_field_benchmark.runs of --config")
    parser.add_argument("--increments", type=int, default=None, help="default: phase_field_benchmark.increments")
    parser.add_argument("--process-zone", default=None, help="JSON of the process-zone settings; default: ifenn.process_zone of --config")
    parser.add_argument("--verification", default=None, help="JSON of the verified step's settings; default: ifenn.verification of --config")
    parser.add_argument("--out", default="results/benchmarks/phase_field_speed.csv")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    import torch

    torch.set_num_threads(1)
    config = load_config(*args.config)
    setup = config["phase_field_benchmark"]
    if args.specs:
        specs = [json.loads(Path(path).read_text()) for path in args.specs]
    else:
        specs = [ifenn_run_spec(config, run) for run in setup["runs"]]
    zone = json.loads(args.process_zone) if args.process_zone else config["ifenn"]["process_zone"]
    verification = json.loads(args.verification) if args.verification else config["ifenn"]["verification"]
    table = phase_field_speed(specs, zone, args.model, args.increments or setup["increments"], verification=verification)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print("\nPhase-field step, seconds per increment (mean over the increments after the switch-over):")
        print(table[["run", "pixels", "method", "network_kernel", "increments", "t_displacement_s", "t_phase_field_s", "t_phase_field_median_s",
                     "evaluated_fraction", "t_verify_s", "verify_corrected_fraction", "phase_field_speedup_vs_fem", "final_force"]].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
