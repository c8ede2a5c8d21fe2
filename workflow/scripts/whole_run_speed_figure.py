"""Adapter: the whole-run benchmark's tables -> ifenn.studies.figures.whole_run_speed_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import whole_run_speed_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
whole_run_speed_figure(pd.read_csv(snakemake.input.increments), pd.read_csv(snakemake.input.summary), snakemake.output[0])
