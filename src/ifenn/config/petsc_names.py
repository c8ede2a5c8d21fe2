"""PETSc option values the config can check before a run: type names (read from PETSc in a child
process) and positive tolerances and iteration limits."""

from __future__ import annotations

import functools
import json
from pathlib import Path

#: PETSc options whose value names a PETSc type, and the petsc4py enumeration of its names
_PETSC_TYPE_OPTIONS = {"ksp_type": "KSP", "pc_type": "PC", "pc_factor_mat_solver_type": "SOLVER", "pc_factor_mat_ordering_type": "ORDERING"}


_PETSC_NAMES_SCRIPT = """
import json
from petsc4py import PETSc
enums = {"KSP": PETSc.KSP.Type, "PC": PETSc.PC.Type, "SOLVER": PETSc.Mat.SolverType, "ORDERING": PETSc.Mat.OrderingType}
print(json.dumps({kind: sorted({getattr(e, n) for n in dir(e) if not n.startswith("_") and isinstance(getattr(e, n), str)})
                  for kind, e in enums.items()}))
"""


@functools.cache
def _petsc_type_names() -> dict | None:
    """PETSc's type names by kind (KSP, PC, SOLVER, ORDERING), read in a child process: importing
    petsc4py starts MPI, and a Snakemake process with MPI started passes MPI's environment to
    the jobs it submits (sbatch --export=ALL), where mpirun then exits 1 without a word (seen
    under SLURM). None where petsc4py is missing (PETSc checks the names when a run starts)."""
    import importlib.util
    import subprocess
    import sys

    if importlib.util.find_spec("petsc4py") is None:
        return None
    done = subprocess.run([sys.executable, "-c", _PETSC_NAMES_SCRIPT], capture_output=True, text=True)
    return json.loads(done.stdout) if done.returncode == 0 else None


def _python_class_exists(path: str) -> bool:
    """Whether ``module.Class`` names a class defined in a module found on the path. Read, not
    imported: importing it here would initialise PETSc and MPI in the Snakemake process, whose
    mpirun children then fail without a word (Open MPI's singleton environment)."""
    import ast
    import importlib.util

    module, _, name = path.rpartition(".")
    try:
        found = importlib.util.find_spec(module) if module else None
    except (ImportError, ValueError):
        return False
    if found is None or not found.origin or not found.origin.endswith(".py"):
        return False
    tree = ast.parse(Path(found.origin).read_text())
    return any(isinstance(node, ast.ClassDef) and node.name == name for node in tree.body)


def petsc_problems(key: str, options: dict) -> list[str]:
    """Values of PETSc options that PETSc would refuse only inside a run: an unknown type name
    (``ksp_type``, ``pc_type``, the factor's solver and ordering, also behind a ``sub_`` or
    ``mg_levels_`` prefix) and a tolerance or iteration limit that is not a positive number."""
    names = _petsc_type_names() or {}
    problems = []
    for option, value in options.items():
        base = option.removeprefix("sub_").removeprefix("mg_levels_").removeprefix("mg_coarse_")
        if base in _PETSC_TYPE_OPTIONS:
            allowed = names.get(_PETSC_TYPE_OPTIONS[base])
            if allowed is not None and str(value) not in allowed:
                problems.append(f"config key '{key}.{option}': {value!r} is not a PETSc type of that kind; allowed: {allowed}")
        elif base == "pc_python_type" and not _python_class_exists(str(value)):   # a python preconditioner
            problems.append(f"config key '{key}.{option}': {value!r} is not a module.Class found here "
                            "(e.g. ifenn.fem.factor.NestedDissectionCholesky)")
        elif base.endswith(("_rtol", "_atol", "_max_it")):
            integral = base.endswith("_max_it")
            good = isinstance(value, int if integral else (int, float)) and not isinstance(value, bool) and value > 0
            if not good:
                problems.append(f"config key '{key}.{option}': {value!r} must be a positive {'integer' if integral else 'number'}")
    return problems
