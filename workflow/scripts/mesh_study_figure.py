"""Adapter: FEM/IFENN pairs on several meshes -> ifenn.studies.figures.mesh_study_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import mesh_study_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
cases = [{"label": run, "fem_history": pd.read_csv(p["fem_history"]), "ifenn_history": pd.read_csv(p["ifenn_history"]),
          "fem_fields": p["fem_fields"], "ifenn_fields": p["ifenn_fields"]} for run, p in snakemake.params.pairs.items()]
options = snakemake.params.options
mesh_study_figure(cases, snakemake.output[0], options["u_max"], zoom=options.get("zoom"))
