"""Adapter: FEM at h, the finer FEM and the adaptive runs -> ifenn.studies.tables.adaptive_resolution's table,
the force-curve figure and a picture of each adaptive run's mesh at three load levels."""
from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])

from ifenn.io import write_csv  # noqa: E402
from ifenn.run_files import read_spec  # noqa: E402
from ifenn.studies.figures import adaptive_mesh_figure, adaptive_resolution_figure  # noqa: E402
from ifenn.studies.tables.adaptive_resolution import (  # noqa: E402
    adaptive_resolution_curves,
    adaptive_resolution_table,
    mesh_states,
    tree_maker,
)

cases = snakemake.params.cases
table = adaptive_resolution_table(cases)
write_csv(snakemake.output.table, table)
adaptive_resolution_figure(adaptive_resolution_curves(cases), table, snakemake.output.figure)
first = next(iter(cases.values()))
run, folder = next(iter(first["adaptive_dirs"].items()))
adaptive_mesh_figure(mesh_states(folder), tree_maker(read_spec(folder)), snakemake.output.mesh,
                     title=f"{run}: the displacement mesh over the phase field")
