"""The phase-field step over the whole run, FEM against whole-path IFENN (the verified step from
the first increment), snt1/snt2/snt3 (config 'whole_run_benchmark'): one process, one core, the
two runs' increments interleaved (see ifenn.whole_run_benchmark). Needs the meshes and the trained
PICNN of the workflow (results/), no FEM run. Run it alone: the numbers are wall times.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/whole_run_speed.py [--increments N] [--out CSV]
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import pandas as pd

from ifenn.config import REPO, ifenn_run_spec, load_config
from ifenn.io import write_csv
from ifenn.whole_run_benchmark import whole_run_speed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", nargs="+", default=[str(REPO / "config" / "config.yaml")])
    parser.add_argument("--model", default="results/picnn/model.pt")
    parser.add_argument("--specs", nargs="+", default=None,
                        help="whole-path IFENN run specs (results/ifenn/RUN/spec.json); default: whole_run_benchmark.runs of --config")
    parser.add_argument("--increments", type=int, default=None, help="first increments of each schedule (default: all)")
    parser.add_argument("--out", default="results/benchmarks/whole_run_speed.csv")
    parser.add_argument("--out-increments", default="results/benchmarks/whole_run_speed_increments.csv")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    import torch

    torch.set_num_threads(1)
    if args.specs:
        specs = [json.loads(Path(path).read_text()) for path in args.specs]
    else:
        config = load_config(*args.config)
        specs = [ifenn_run_spec(config, run) for run in config["whole_run_benchmark"]["runs"]]
    summary, increments = whole_run_speed(specs, args.model, increments=args.increments)
    write_csv(args.out, summary)
    write_csv(args.out_increments, increments)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print("\nPhase-field step over the whole run (s):")
        print(summary[["run", "method", "elements", "increments", "t_phase_field_total_s", "t_phase_field_median_s",
                       "t_phase_field_pre_nucleation_s", "t_phase_field_propagation_s", "phase_field_speedup_vs_fem",
                       "pre_nucleation_speedup_vs_fem", "propagation_speedup_vs_fem", "final_force"]].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
