"""What a network is worth to the verified step (ifenn.studies.drivers.network_worth): the
correction's CG iterations and the step's time per warm start (no network, the paper's network,
extrapolation, and the two oracles that bound any network of that role), on the history images of
each run's own verified loop. Needs the FEM runs, meshes and trained PICNN of the workflow
(results/). Run it alone: the times are wall times.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/network_worth.py [--increments N] [--out CSV]

Writes the summary (--out), the rows per increment (beside it, _increments.csv) and the figure (--figure).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from _cli import parser, run_inputs, setup

from ifenn.io import atomic_path
from ifenn.studies.drivers.network_worth import network_worth
from ifenn.studies.figures import network_worth_figure


def main() -> int:
    cli = parser(__doc__, "network_worth", "results/benchmarks/network_worth.csv", "default: network_worth.increments")
    cli.add_argument("--figure", default="results/figures/network_worth.png")
    args = cli.parse_args()
    config, specs = setup(args, "network_worth")
    summary, rows = network_worth(specs, run_inputs(specs, args.results), args.model, args.increments or config["network_worth"]["increments"])
    for table, path in ((summary, Path(args.out)), (rows, Path(args.out).with_name(Path(args.out).stem + "_increments.csv"))):
        with atomic_path(path) as tmp:
            table.to_csv(tmp, index=False)
    network_worth_figure(summary, args.figure)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print(summary.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
