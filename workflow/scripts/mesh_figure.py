"""Adapter: scene config -> ifenn.plots.mesh_figure (PNG)."""
from ifenn.mesh import build_mesh
from ifenn.plots import mesh_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
mesh_figure(build_mesh(snakemake.params.scene), snakemake.params.scene, snakemake.wildcards.scene, snakemake.output[0])
