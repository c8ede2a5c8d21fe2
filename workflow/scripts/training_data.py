"""Adapter: FEM fields.h5 -> ifenn.network.training_data.extract_training_data."""
from ifenn.io import log_to
from ifenn.network.training_data import extract_training_data

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
extract_training_data(snakemake.input.fields, snakemake.params.increments, snakemake.output[0])
