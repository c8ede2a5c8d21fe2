"""The phase-field step, FEM against IFENN with full-image, process-zone and verified inference,
on snt1/snt2/snt3 (config 'phase_field_benchmark'): same process, same core, same loads from
each FEM run's switch-over state (see ifenn.studies.drivers.benchmark). Needs the FEM runs and the trained
PICNN of the workflow (results/). Run it alone: the numbers are wall times.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/phase_field_speed.py [--increments N] [--out CSV]
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from _cli import devices, parser, run_inputs, setup

from ifenn.studies.drivers.benchmark import phase_field_speed


def main() -> int:
    cli = parser(__doc__, "phase_field_benchmark", "results/benchmarks/phase_field_speed.csv", "default: phase_field_benchmark.increments")
    cli.add_argument("--process-zone", default=None, help="JSON of the process-zone settings; default: ifenn.process_zone of --config")
    cli.add_argument("--verification", default=None, help="JSON of the verified step's settings; default: ifenn.verification of --config")
    args = cli.parse_args()
    config, specs = setup(args, "phase_field_benchmark")
    setup_section = config["phase_field_benchmark"]
    zone = json.loads(args.process_zone) if args.process_zone else config["ifenn"]["process_zone"]
    verification = json.loads(args.verification) if args.verification else config["ifenn"]["verification"]
    table = phase_field_speed(specs, run_inputs(specs, args.results), zone, args.model, args.increments or setup_section["increments"],
                              verification=verification, devices=devices(args))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print("\nPhase-field step, seconds per increment (mean over the increments after the switch-over):")
        print(table[["run", "pixels", "method", "device", "network_kernel", "increments", "t_displacement_s", "t_phase_field_s", "t_phase_field_median_s",
                     "evaluated_fraction", "t_verify_s", "verify_corrected_fraction", "phase_field_speedup_vs_fem", "final_force"]].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
