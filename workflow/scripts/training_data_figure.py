"""Adapter: training data -> ifenn.studies.figures.training_data_figure."""
from ifenn.io import log_to
from ifenn.network.training_data import read_training_data
from ifenn.studies.figures import training_data_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
training_data_figure(read_training_data(snakemake.input[0]), snakemake.output[0])
