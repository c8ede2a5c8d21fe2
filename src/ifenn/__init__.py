"""Hybrid FEM + neural-network phase-field fracture (IFENN), reproducible workflow.

Modules: ``config`` (validated configuration), ``mesh`` (structured Q1 meshes with slit
notches), ``physics`` (UFL forms), ``solver`` (staggered FEM loop), ``pixels`` (Gauss point
<-> pixel maps), ``io`` (atomic files, provenance), ``plots``. Modules that need dolfinx
import it themselves, so the config, pixels and PICNN parts work without it.
"""

__version__ = "0.1.0"

# torch before dolfinx, in every process: dolfinx's libraries are opened RTLD_GLOBAL, and
# once they are loaded their BLAS serves torch's own matrix products (torch.mm ~13x slower
# here, measured; the convolutions, done by oneDNN, are not affected). Costs ~1.5 s per process.
try:
    import torch  # noqa: F401
except ImportError:  # the config and mesh parts work without torch
    pass
