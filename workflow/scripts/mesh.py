"""Adapter: scene config -> ifenn.mesh.build_mesh -> XDMF/HDF5 + JSON metadata."""
from ifenn.mesh import build_mesh, write_mesh

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
write_mesh(build_mesh(snakemake.params.scene), snakemake.output.xdmf)
