"""Adapter: FEM and IFENN histories -> ifenn.metrics.timing, rows per run and method."""
import pandas as pd

from ifenn.io import write_csv
from ifenn.metrics import timing

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
rows = []
for run, fem_run in snakemake.params.runs.items():
    fem = pd.read_csv(f"results/fem/{fem_run}/history.csv")
    ifenn = pd.read_csv(f"results/ifenn/{run}/history.csv")
    rows += [{"run": run, "fem_run": fem_run, **row} for row in timing(fem, ifenn)]
write_csv(snakemake.output[0], pd.DataFrame(rows))
