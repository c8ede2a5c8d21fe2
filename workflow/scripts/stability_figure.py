"""Adapter: results/tables/stability.csv -> the stability map."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import stability_map_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
stability_map_figure(pd.read_csv(snakemake.input[0]), snakemake.output[0])
