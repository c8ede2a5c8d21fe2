"""Adapter: run histories (+ the phase-field benchmark, quoted in the figure) -> ifenn.studies.tables.speed_accuracy table and figure."""
import pandas as pd

from ifenn.io import log_to, write_csv
from ifenn.studies.figures import speed_accuracy_figure
from ifenn.studies.tables.speed_accuracy import speed_accuracy_table

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
table = speed_accuracy_table(snakemake.params.setups, snakemake.params.run_dirs)
write_csv(snakemake.output.table, table)
speed_accuracy_figure(table, snakemake.output.figure, pd.read_csv(snakemake.input.benchmark))
