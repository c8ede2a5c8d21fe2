"""Adapter: timing table -> ifenn.studies.figures.phase_field_time_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import phase_field_time_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
phase_field_time_figure(pd.read_csv(snakemake.input.timing), snakemake.params.cases, snakemake.output[0])
