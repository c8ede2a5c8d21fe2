"""Adapter: FEM and IFENN run folders -> ifenn.metrics.accuracy, one row per IFENN run."""
import pandas as pd

from ifenn.io import write_csv
from ifenn.metrics import accuracy

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
rows = [{"run": run, "fem_run": where["fem_run"], **accuracy(where["fem_dir"], where["ifenn_dir"], snakemake.params.material)}
        for run, where in snakemake.params.runs.items()]
write_csv(snakemake.output[0], pd.DataFrame(rows))
