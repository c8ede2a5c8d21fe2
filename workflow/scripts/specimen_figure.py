"""Adapter: the specimen's FEM histories, the first run's phi and the measured curve -> ifenn.studies.plots.specimen_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.run_files import read_phase_field_maps
from ifenn.studies.plots import specimen_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
curves = {f"FEM {run}": pd.read_csv(path) for run, path in zip(snakemake.params.runs, snakemake.input.histories, strict=True)}
curves.update({f"IFENN {run}": pd.read_csv(path) for run, path in zip(snakemake.params.ifenn_runs, snakemake.input.ifenn, strict=True)})
curves.update({f"adaptive {run}": pd.read_csv(path)
               for run, path in zip(snakemake.params.adaptive_runs, snakemake.input.adaptive, strict=True)})
maps, attrs = read_phase_field_maps(snakemake.input.fields)
specimen_figure(curves, pd.read_csv(snakemake.input.measured, comment="#"), snakemake.params.label, maps, attrs,
                snakemake.params.scene, snakemake.output[0], title=snakemake.wildcards.specimen)
