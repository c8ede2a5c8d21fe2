"""Adapter: run histories (+ the phase-field benchmark, quoted in the figures) -> ifenn.studies.tables.speed_accuracy table and a figure per scene."""
import pandas as pd

from ifenn.io import log_to, write_csv
from ifenn.studies.figures import speed_accuracy_figure
from ifenn.studies.tables.speed_accuracy import speed_accuracy_table

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
table = speed_accuracy_table(snakemake.params.setups, snakemake.params.run_dirs)
write_csv(snakemake.output.table, table)
benchmark = pd.read_csv(snakemake.input.benchmark)
for scene, path in zip(snakemake.params.setups, snakemake.output.figures, strict=True):   # one figure per scene, in the config's order
    speed_accuracy_figure(table, scene, path, benchmark)
