"""Adapter: history.csv -> ifenn.studies.figures.force_displacement_figure (PNG)."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import force_displacement_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
run = snakemake.wildcards.run
force_displacement_figure({f"FEM {run}": pd.read_csv(snakemake.input.history)}, snakemake.output[0], title=f"{run}: FEM reference",
                          force_unit=snakemake.params.force_unit)
