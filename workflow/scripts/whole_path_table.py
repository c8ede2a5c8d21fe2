"""Adapter: whole-path IFENN and FEM run folders -> ifenn.whole_path tables and figure."""
import json
import logging
import sys

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_stream = open(snakemake.log[0], "w", buffering=1)  # noqa: SIM115 (open for the whole script)
sys.stderr = log_stream
logging.basicConfig(stream=log_stream, level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")

import pandas as pd  # noqa: E402

from ifenn.io import write_csv  # noqa: E402
from ifenn.plots import whole_path_figure  # noqa: E402
from ifenn.whole_path import network_before_nucleation, whole_path_table  # noqa: E402

runs = snakemake.params.runs
table = whole_path_table(runs, "results", snakemake.params.switch_phi_max, snakemake.params.targets)
write_csv(snakemake.output.table, table)
frames = []
for run in snakemake.params.network_runs:
    spec = json.loads(open(f"results/ifenn/{run}/spec.json").read())
    history = pd.read_csv(f"results/ifenn/{run}/history.csv")
    frames.append(network_before_nucleation(spec, f"results/fem/{runs[run]}/fields.h5", "results/picnn/model.pt", history)
                  .assign(run=run, fem_run=runs[run]))
network = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["run", "fem_run", "increment"])
write_csv(snakemake.output.network, network[["run", "fem_run", *[c for c in network.columns if c not in ("run", "fem_run")]]])
pairs = {run: (pd.read_csv(f"results/fem/{fem}/history.csv"), pd.read_csv(f"results/ifenn/{run}/history.csv")) for run, fem in runs.items()}
whole_path_figure(pairs, table, snakemake.output.figure)
