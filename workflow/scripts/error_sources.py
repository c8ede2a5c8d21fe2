"""Adapter: IFENN runs, their FEM states and the network -> ifenn.studies.drivers.error_sources tables and figure."""
import os

from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
os.environ.setdefault("OMP_NUM_THREADS", str(snakemake.threads))

import torch  # noqa: E402

from ifenn.io import write_csv  # noqa: E402
from ifenn.studies.drivers.error_sources import error_sources  # noqa: E402
from ifenn.studies.figures import error_sources_figure  # noqa: E402

torch.set_num_threads(snakemake.threads)
sources, states = error_sources(snakemake.params.cases, snakemake.params.stagger_max_iterations, snakemake.params.crack_phi,
                                snakemake.params.device)
write_csv(snakemake.output.states, states)
write_csv(snakemake.output.table, sources)
error_sources_figure(sources, snakemake.output.figure)
