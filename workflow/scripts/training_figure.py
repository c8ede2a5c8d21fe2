"""Adapter: training data, model, loss log -> ifenn.studies.figures.training_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.network.picnn import load_picnn
from ifenn.network.training_data import read_training_data
from ifenn.studies.figures import training_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
model, _ = load_picnn(snakemake.input.model)
training_figure(read_training_data(snakemake.input.data), model, pd.read_csv(snakemake.input.loss), snakemake.output[0])
