"""Phase-field steps: what replaces phi after the history update, inside one staggered
iteration. The staggered loop calls ``solve()``; each step updates
``problem.phase_field_gp`` (and, for FEM, the nodal ``problem.phase_field``).

FEMPhaseField solves -Gc lc Lap(phi) + (Gc/lc + 2H) phi = 2H with Q1 elements. The
hybrid IFENN step (:class:`ifenn.hybrid.pixel_step.PixelPhaseField`) plugs into the same
interface (:class:`PhaseFieldStep`).
"""

from __future__ import annotations

from typing import Protocol

import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from ifenn.fem.problem import FractureProblem, check_converged, configure_ksp


class PhaseFieldStep(Protocol):
    """What the staggered loop needs of a phase-field step."""

    name: str
    #: history.csv columns the step adds, and their values for the current increment (summed
    #: over its staggered iterations; the loop zeroes them at the start of each increment)
    extra_columns: tuple[str, ...]
    timings: dict

    def solve(self) -> int:
        """Replace phi from the current history (``problem.phase_field_gp``, and the nodal field
        where the step has one); returns the solver's iterations (0 if none)."""

    def phase_field_max(self) -> float: ...


class FEMPhaseField:
    """Nodal Q1 phase-field solve (forms, matrix and KSP built once)."""

    name = "fem"
    extra_columns = ()

    def __init__(self, problem: FractureProblem, options: dict):
        self.problem = problem
        p, q = ufl.TrialFunction(problem.W), ufl.TestFunction(problem.W)
        a, L = problem.model.phase_field_forms(p, q, problem.history, problem.material)
        self.a = fem.form(a * problem.dx)
        self.L = fem.form(L * problem.dx)
        self.A = fem_petsc.create_matrix(self.a)
        self.b = fem_petsc.create_vector(self.L)
        self.ksp = PETSc.KSP().create(problem.comm)
        self.ksp.setOperators(self.A)
        configure_ksp(self.ksp, "phase_field_", options)
        if self.ksp.getType() != PETSc.KSP.Type.PREONLY:
            self.ksp.setInitialGuessNonzero(True)
        self._at_gauss_points = fem.Expression(problem.phase_field, problem.quadrature_points)
        self.timings: dict = {}

    def solve(self) -> int:
        """Assemble with the current history, solve for nodal phi, evaluate it at the Gauss
        points. Returns the Krylov iterations."""
        problem = self.problem
        self.A.zeroEntries()
        fem_petsc.assemble_matrix(self.A, self.a)
        self.A.assemble()
        with self.b.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.ksp.solve(self.b, problem.phase_field.vector)
        problem.phase_field.x.scatter_forward()
        iterations = check_converged(self.ksp, "phase-field")
        problem.phase_field_gp.x.array[problem.q_dofs] = self._at_gauss_points.eval(problem.local_cells)
        return iterations

    def phase_field_max(self) -> float:
        return self.problem.max_owned(self.problem.phase_field)
