"""Hybrid FEM + neural-network phase-field fracture (IFENN), reproducible workflow.

Layout, one room per concern:

- top level: ``config`` (validated configuration, run specs), ``specs`` (the run specs as types), ``io`` (atomic files, logs,
  progress), ``run_files`` (the formats of a run directory), ``pixels`` (the Gauss-point pixel
  grid the layers below share), ``materials`` (a scene's material, lc/h), ``geometry``;
- ``models``: the phase-field model (degradation, crack density, driving force, forms);
- ``pixel_equation``: the pixel equation (definition, numpy and torch backends);
- ``fem``: the finite-element core (mesh, elasticity, problem, FEM phase-field step, load control,
  staggered loop);
- ``network``: the PICNN, its compiled evaluation and its training;
- ``hybrid``: IFENN's phase-field step, process-zone inference, the verified step, hybrid runs;
- ``adaptive``: the displacement mesh that follows the crack;
- ``studies``: drivers, tables and figures; ``tooling``: the workflow's own bookkeeping.

Modules that need dolfinx import it themselves, so the config, pixels and PICNN parts work
without it.
"""

__version__ = "0.1.0"

import importlib.abc
import sys

#: the modules that load PETSc's and dolfinx's shared libraries
_DOLFINX_STACK = frozenset({"dolfinx", "petsc4py", "basix", "ffcx"})


class _TorchBeforeDolfinx(importlib.abc.MetaPathFinder):
    """torch before dolfinx, in every process that imports both: dolfinx's libraries are opened
    RTLD_GLOBAL, and once they are loaded their BLAS serves torch's own matrix products (torch.mm
    ~13x slower here, measured; the convolutions, done by oneDNN, are not affected). torch costs
    ~1.5 s per process, so it is imported only when the first of dolfinx's stack is, not by every
    figure or table job (most of the quick DAG's jobs)."""

    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in _DOLFINX_STACK and "torch" not in sys.modules:
            sys.meta_path.remove(self)
            try:
                import torch  # noqa: F401
            except ImportError:  # the config and mesh parts work without torch
                pass
        return None  # the ordinary finders import the module itself


if "torch" not in sys.modules and not any(name in sys.modules for name in _DOLFINX_STACK):
    sys.meta_path.insert(0, _TorchBeforeDolfinx())
