"""Phase-field steps: what replaces phi after the history update, inside one staggered
iteration. The staggered loop calls ``solve()``; each step updates
``problem.phase_field_gp`` (and, for FEM, the nodal ``problem.phase_field``).

FEMPhaseField solves -Gc lc Lap(phi) + (Gc/lc + 2H) phi = 2H with Q1 elements. The
hybrid IFENN steps (PICNN, exact pixel solver) plug into the same interface.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from . import physics
from .problem import FractureProblem, check_converged, configure_ksp


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
        a, L = physics.phase_field_forms(p, q, problem.history, problem.material)
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


class PixelPhaseField:
    """The IFENN phase-field step (steps 2-4 of the hybrid increment):

    H at Gauss points -> pixels, capped to [0, H_cap] -> inference (predictor + optional
    Gaussian smoothing) -> Gauss points, with irreversibility phi_gp = max(phi_gp, new).

    ``inference`` (see :mod:`ifenn.process_zone`) maps a capped (ny, nx) history image
    (N/mm^2) to a phi image: the trained PICNN on the whole image or on the process zone
    only, or the exact solution of the same pixel equation (``picnn.solve_pixel_equation``),
    which separates network error from coupling error. Pixel work happens on rank 0;
    Gauss-point fields are scattered back to every rank.
    """

    #: columns of a verified step (:class:`ifenn.verification.VerifiedInference`): share of
    #: the image corrected, max |r| before and after the correction, the correction's work in
    #: whole-image CG iterations (load-independent), check + correction time;
    #: over the staggered iterations of an increment the share and time are summed, the
    #: residuals are those of the last iteration
    VERIFY_COLUMNS = ("verify_corrected_fraction", "verify_residual_before", "verify_residual_after", "verify_solve_work",
                      "t_verify_s")

    def __init__(self, problem: FractureProblem, inference, name: str, history_cap: float, irreversible: bool = True,
                 verified: bool = False):
        """``verified``: ``inference`` (on rank 0) is a :class:`ifenn.verification.VerifiedInference`."""
        self.problem, self.inference, self.name = problem, inference, name
        self.history_cap, self.irreversible, self.verified = history_cap, irreversible, verified
        self._started = False
        self.extra_columns = ("t_inference_s", "evaluated_fraction") + (self.VERIFY_COLUMNS if self.verified else ())
        self._new_phase_field = fem.Function(problem.Q)
        self.timings = dict.fromkeys(self.extra_columns, 0.0)

    def solve(self) -> int:
        problem = self.problem
        if self.verified and not self._started:  # the phase field the run continues from (collective)
            start = problem.pixels_from_gauss_points(problem.phase_field_gp)
            if start is not None:
                self.inference.start_from(start)
            self._started = True
        image = problem.pixels_from_gauss_points(problem.history)
        phi = None
        if image is not None:
            phi = self.inference(np.clip(image, 0.0, self.history_cap))
            # summed over staggered iterations, like the other timings
            self.timings["t_inference_s"] += self.inference.t_network
            self.timings["evaluated_fraction"] += self.inference.evaluated_fraction
            if self.verified:
                self.timings["verify_corrected_fraction"] += self.inference.corrected_fraction
                self.timings["verify_residual_before"] = self.inference.residual_before
                self.timings["verify_residual_after"] = self.inference.residual_after
                self.timings["verify_solve_work"] += self.inference.solve_work
                self.timings["t_verify_s"] += self.inference.t_check + self.inference.t_correction
        problem.gauss_points_from_pixels(phi, self._new_phase_field)
        new = self._new_phase_field.x.array
        if self.irreversible:
            np.maximum(problem.phase_field_gp.x.array, new, out=problem.phase_field_gp.x.array)
        else:
            problem.phase_field_gp.x.array[:] = new
        return 0

    def phase_field_max(self) -> float:
        return self.problem.max_owned(self.problem.phase_field_gp)
