"""Adapter: FEM at h, the finer FEM and IFENN run folders -> ifenn.studies.tables.reference_convergence table and figure."""
from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])

from ifenn.io import write_csv  # noqa: E402
from ifenn.studies.figures import reference_convergence_figure  # noqa: E402
from ifenn.studies.tables.reference_convergence import reference_convergence_curves, reference_convergence_table  # noqa: E402

cases = snakemake.params.cases
table = reference_convergence_table(cases)
write_csv(snakemake.output.table, table)
reference_convergence_figure(reference_convergence_curves(cases), table, snakemake.output.figure)
