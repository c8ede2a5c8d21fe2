"""The phase-field step over the whole run, FEM against whole-path IFENN (the verified step from
the first increment), snt1/snt2/snt3 (config 'whole_run_benchmark'): one process, one core, the
two runs' increments interleaved (see ifenn.studies.drivers.whole_run_benchmark). Needs the meshes and the trained
PICNN of the workflow (results/), no FEM run. Run it alone: the numbers are wall times.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/whole_run_speed.py [--increments N] [--out CSV]
"""

from __future__ import annotations

import pandas as pd
from _cli import devices, parser, run_inputs, setup

from ifenn.io import write_csv
from ifenn.studies.drivers.whole_run_benchmark import whole_run_speed


def main() -> int:
    cli = parser(__doc__, "whole_run_benchmark", "results/benchmarks/whole_run_speed.csv", "first increments of each schedule (default: all)")
    cli.add_argument("--out-increments", default="results/benchmarks/whole_run_speed_increments.csv")
    args = cli.parse_args()
    _, specs = setup(args, "whole_run_benchmark")
    summary, increments = whole_run_speed(specs, run_inputs(specs, args.results), args.model, increments=args.increments,
                                          devices=devices(args))
    write_csv(args.out, summary)
    write_csv(args.out_increments, increments)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print("\nPhase-field step over the whole run (s):")
        print(summary[["run", "method", "device", "elements", "increments", "t_phase_field_total_s", "t_phase_field_median_s",
                       "t_phase_field_pre_nucleation_s", "t_phase_field_propagation_s", "phase_field_speedup_vs_fem",
                       "pre_nucleation_speedup_vs_fem", "propagation_speedup_vs_fem", "final_force"]].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
