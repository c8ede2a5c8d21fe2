"""Adapter: FEM and IFENN histories -> ifenn.studies.tables.metrics.timing, rows per run and method."""
import pandas as pd

from ifenn.io import log_to, write_csv
from ifenn.run_files import read_history
from ifenn.studies.tables.metrics import timing

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
rows = []
for run, where in snakemake.params.runs.items():
    fem, ifenn = read_history(where["fem_dir"]), read_history(where["ifenn_dir"])
    rows += [{"run": run, "fem_run": where["fem_run"], **row} for row in timing(fem, ifenn)]
write_csv(snakemake.output[0], pd.DataFrame(rows))
