"""Adapter: stability cells -> ifenn.stability.stability_table (metrics and labels)."""
from ifenn.io import write_csv
from ifenn.stability import stability_table

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
write_csv(snakemake.output[0], stability_table(snakemake.config, snakemake.params.cell_root))
