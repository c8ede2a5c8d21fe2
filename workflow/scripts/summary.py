"""Adapter: this run's tables and machine_speed.json -> ifenn.studies.tables.summary -> results/summary.md."""
from ifenn.io import log_to
from ifenn.studies.tables.summary import write_summary

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
write_summary(snakemake.output[0], dict(snakemake.params.tables), snakemake.input.machine,
              snakemake.params.config_files)
