"""Adapter: FEM and IFENN histories -> ifenn.studies.figures.force_displacement_figure (PNG)."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import force_displacement_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
run, fem_run = snakemake.wildcards.run, snakemake.params.fem_run
ifenn = pd.read_csv(snakemake.input.ifenn)
switch_u = ifenn.u[ifenn.hybrid_active == 1].min()
force_displacement_figure({f"FEM {fem_run}": pd.read_csv(snakemake.input.fem), f"IFENN {run}": ifenn},
                          snakemake.output[0], title=f"{run}: FEM vs IFENN (switch at u = {switch_u:.4g} mm)")
