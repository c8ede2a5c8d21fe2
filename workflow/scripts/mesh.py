"""Adapter: scene config -> ifenn.fem.mesh.build_mesh -> XDMF/HDF5 + JSON metadata."""
from ifenn.fem.mesh import build_mesh, write_mesh
from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
write_mesh(build_mesh(snakemake.params.scene), snakemake.output.xdmf)
