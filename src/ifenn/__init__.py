"""Hybrid FEM + neural-network phase-field fracture (IFENN), reproducible workflow.

Modules: ``config`` (validated configuration), ``mesh`` (structured Q1 meshes with slit
notches), ``physics`` (UFL forms), ``solver`` (staggered FEM loop), ``pixels`` (Gauss point
<-> pixel maps), ``io`` (atomic files, provenance), ``plots``. Modules that need dolfinx
import it themselves, so the config, pixels and PICNN parts work without it.
"""

__version__ = "0.1.0"
