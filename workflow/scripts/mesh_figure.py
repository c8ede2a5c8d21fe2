"""Adapter: scene config -> ifenn.studies.figures.mesh_figure (PNG)."""
from ifenn.fem.mesh import build_mesh
from ifenn.io import log_to
from ifenn.studies.figures import mesh_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
mesh_figure(build_mesh(snakemake.params.scene), snakemake.params.scene, snakemake.wildcards.scene, snakemake.output[0])
