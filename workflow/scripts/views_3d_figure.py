"""Adapter: one FEM/IFENN pair -> ifenn.studies.figures.views_3d_figure."""
from ifenn.io import log_to
from ifenn.studies.figures import views_3d_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
options = snakemake.params.options
views_3d_figure(snakemake.input.fem_fields, snakemake.input.ifenn_fields, options["increment"], options["views"],
                snakemake.output[0], zoom=options.get("zoom"))
