"""Adapter: results/tables/stability.csv -> the stability map."""
import pandas as pd

from ifenn.plots import stability_map_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
stability_map_figure(pd.read_csv(snakemake.input[0]), snakemake.output[0])
