"""Adapter: FEM and IFENN run folders -> ifenn.studies.tables.metrics.accuracy, one row per IFENN run."""
import pandas as pd

from ifenn.io import log_to, write_csv
from ifenn.studies.tables.metrics import accuracy

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
rows = [{"run": run, "fem_run": where["fem_run"], **accuracy(where["fem_dir"], where["ifenn_dir"])}
        for run, where in snakemake.params.runs.items()]
write_csv(snakemake.output[0], pd.DataFrame(rows))
