"""The IFENN phase-field step: the history on the pixel grid, a pixel-image inference, and back
to the Gauss points (the :class:`ifenn.fem.phase_field.PhaseFieldStep` of a hybrid run)."""

from __future__ import annotations

import numpy as np
from dolfinx import fem

from ifenn.fem.problem import FractureProblem


class PixelPhaseField:
    """The IFENN phase-field step (steps 2-4 of the hybrid increment):

    H at Gauss points -> pixels, capped to [0, H_cap] -> inference (predictor + optional
    Gaussian smoothing) -> Gauss points, with irreversibility phi_gp = max(phi_gp, new).

    ``inference`` (see :mod:`ifenn.hybrid.process_zone`) maps a capped (ny, nx) history image
    (N/mm^2) to a phi image: the trained PICNN on the whole image or on the process zone
    only, or the exact solution of the same pixel equation (``ifenn.pixel_equation.numpy_backend.solve_pixel_equation``),
    which separates network error from coupling error. Pixel work happens on rank 0;
    Gauss-point fields are scattered back to every rank.
    """

    #: columns of a verified step (:class:`ifenn.hybrid.verification.VerifiedInference`): share of
    #: the image corrected, max |r| before and after the correction, the correction's work in
    #: whole-image CG iterations (load-independent), check + correction time;
    #: over the staggered iterations of an increment the share and time are summed, the
    #: residuals are those of the last iteration
    VERIFY_COLUMNS = ("verify_corrected_fraction", "verify_residual_before", "verify_residual_after", "verify_solve_work",
                      "t_verify_s")

    def __init__(self, problem: FractureProblem, inference, name: str, history_cap: float, irreversible: bool = True,
                 verified: bool = False):
        """``verified``: ``inference`` (on rank 0) is a :class:`ifenn.hybrid.verification.VerifiedInference`."""
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
            # a verified step caps H itself: for the network, and for its equation unless cap_history is off
            phi = self.inference(np.maximum(image, 0.0) if self.verified else np.clip(image, 0.0, self.history_cap))
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
