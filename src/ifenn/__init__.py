"""Hybrid FEM + neural-network phase-field fracture (IFENN), reproducible workflow.

Layout, one room per concern:

- top level: ``config`` (validated configuration, run specs), ``io`` (atomic files, logs,
  progress), ``run_files`` (the formats of a run directory), ``pixels`` (the Gauss-point pixel
  grid the three layers below share);
- ``fem``: the finite-element core (mesh, forms, problem, FEM phase-field step, load control,
  staggered loop);
- ``network``: the PICNN, its compiled evaluation and its training;
- ``hybrid``: IFENN's phase-field step, process-zone inference, the verified step, hybrid runs;
- ``studies``: metrics, figures, benchmarks, the stability sweep and the error split.

Modules that need dolfinx import it themselves, so the config, pixels and PICNN parts work
without it.
"""

__version__ = "0.1.0"

# torch before dolfinx, in every process: dolfinx's libraries are opened RTLD_GLOBAL, and
# once they are loaded their BLAS serves torch's own matrix products (torch.mm ~13x slower
# here, measured; the convolutions, done by oneDNN, are not affected). Costs ~1.5 s per process.
try:
    import torch  # noqa: F401
except ImportError:  # the config and mesh parts work without torch
    pass
