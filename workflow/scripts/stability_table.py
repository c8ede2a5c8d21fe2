"""Adapter: stability cells -> ifenn.studies.drivers.stability.stability_table (metrics and labels)."""
from ifenn.io import log_to, write_csv
from ifenn.studies.drivers.stability import stability_table

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
write_csv(snakemake.output[0], stability_table(snakemake.config, snakemake.params.cell_root))
