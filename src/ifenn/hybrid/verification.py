"""Verified phase-field step: every prediction checked by the pixel equation it was trained
on, and corrected where it fails.

The pixel equation (the PICNN's physics loss, :func:`ifenn.pixel_equation.torch_backend.residual`) at pixel i:

    R_i(phi) = (Gc/lc + 2 H_i) phi_i - D (K9*(phi)_i - 3 phi_i) - 2 H_i,   D = Gc lc / h_px^2,

with H the capped history (the network's input; H itself, FEM's equation, with ``cap_history``
false) and the Laplacian's padding ("replicate":
zero flux, or "zeros"). Written as A phi = 2 H, A is a strictly diagonally dominant M-matrix:
off-diagonal entries -D w_ij <= 0 and every row sums to at least a_i = Gc/lc + 2 H_i (exactly
a_i with zero flux; more with zeros padding, which drops the neighbours beyond the image).

Normalisation and what the tolerance means. The check uses r_i = R_i / a_i, a phase field
(dimensionless). For any M-matrix of that kind, ||A^-1 R||_inf <= max_i |R_i| / a_i (take
the pixel i where the error e = phi - phi* is largest: |R_i| = |a_i e_i + sum_j A_ij (e_i -
e_j)... | >= a_i |e_i|, since the off-diagonal part only pulls e_i towards smaller
neighbours). A slit (:class:`ifenn.pixels.SlitCuts`) removes the links that cross it: each cut
takes the same weight off an off-diagonal entry and off the diagonal, so A stays such an M-matrix
with the same row sums, and the bound holds unchanged on a cut grid. So

    max_i |r_i| <= tolerance   implies   max_i |phi_i - phi*_i| <= tolerance,

where phi* is the exact solution of the pixel equation for this H: the check is a
certificate in the max norm, in the units of phi, with no constant to tune. Why the max
norm: the force after a crack has formed is set by the weakest band across it, i.e. by
phi where it is largest; an error of 1e-3 keeps the band's stiffness g = (1 - phi)^2 below
~4e-6 of the intact one where the exact pixel solution reaches 0.999 (the H cap of 5e4
N/mm^2), while a mean-square norm would let a few wrong pixels across the crack through.
The Jacobi-scaled residual R_i / A_ii would not do: the diagonal holds 3 D ~ 4e4 N/mm^2
besides a_i ~ 90 N/mm^2 in the far field, so it under-reports smooth errors 400-fold.

Correction. The pixels with |r_i| > tolerance are grown by ``margin_lc`` phase-field lengths
(the change of phi decays as exp(-d/lc); where a box's new values meet the old ones, the
Laplacian turns a jump delta into |r| ~ (lc/h_px)^2 delta, so the margin must take the change
down by that factor: 6 lc at lc/h_px = 12) and grouped into boxes (the connected groups' bounding boxes); on each box the pixel equation is solved
with the values around it as Dirichlet data (the image's own padding where the box meets
the image edge) by conjugate gradients preconditioned with one multigrid V-cycle (compiled:
``ifenn_pixel_mg_pcg`` in ``orbit_kernel.cpp``; cell-centred, Jacobi smoothing, bilinear
transfers, coarse operators re-discretised with the slits' links cut at each level's spacing), for the correction of the candidate, until
max |r| <= ``solve_fraction`` x tolerance inside the box. Without the compiled kernel the
fallback is CG preconditioned with the constant-coefficient operator's fast sine transform.
The V-cycle reduces the residual about tenfold per iteration whatever the box size and
however rough the error (Jacobi removes pixel-scale roughness, the coarse levels the smooth
part): 3-4 iterations per increment on snt1 from the last verified phi, against 31-39 for
the sine-transform CG, whose constant coefficient min(a) misses the crack's a ~ 1e5. The pixels next
to a box see its new values, so the check runs again there; boxes that still fail grow
and are solved again, up to ``max_rounds``. A step that still fails after that is reported
(``verify_residual_after`` > tolerance), never passed on silently.

Warm starts ("what the network is worth"): ``network`` takes the network's prediction where
it changed since the last step and the last verified phi elsewhere; ``increment`` adds the
change of the network's prediction to the last verified phi (the network as a predictor of
the change, whose error is smaller where the network's error is systematic); ``previous``
ignores the network and starts from the last verified phi (the correction alone is then a
local pixel solver of the changed region). The check itself is the same, and so is the
result, to the tolerance. What differs is the cost, measured at snt3-II (600 x 600 pixels, 40
increments of propagation, one core, the phase-field benchmark): ``network`` with the network
asked on the process zone's tolerance (3e-3) needs 4.2 whole-image CG iterations per increment
and 0.040 s per step, ``previous`` 2.6 iterations and 0.018 s, ``increment`` 3.0. The network's own
error is systematic (a bias of ~0.01 in the far field, pixel-scale roughness that the check
amplifies by (lc/h_px)^2), so its prediction is a worse start than the last verified phi
wherever phi moves less than that; its change is not. Hence the default: ``increment``, with
the network asked again only where a pixel's local phase field moved by ``network_tolerance``
(0.1: the crack tip; 0.025 s per step at snt3, the network 0.004 s of it).

Cost. The residual is recomputed only where its inputs changed: pixels whose capped H or
whose candidate phi changed, and their 8 neighbours; elsewhere it is the one that passed
the last check. The first call checks the whole image. The same jump argument makes the
correction nearly global while the load grows: the phase field changes smoothly, by less
than the tolerance, far beyond the failing pixels, and a box's edge turns even a change of
tolerance / (lc/h_px)^2 into a failing residual; and around the peak the history grows on
half the specimen, so the exact phi itself changes by more than the tolerance across it
(snt1-I, increments 300 -> 301: H changes on 49 % of the image, phi by > 1e-3 on 11 %, from
the bottom edge to the top). The boxes then exceed ``GLOBAL_FRACTION`` of the image and
the whole image is solved at once, which the multigrid makes an O(pixels) solve.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ifenn.pixel_equation.numpy_backend import PixelEquation, bounding_box, correction_boxes
from ifenn.pixels import box_area, grow_box
from ifenn.schema import schema_defaults

log = logging.getLogger(__name__)

#: the settings' defaults: those of the config schema ('ifenn.verification')
VERIFICATION_DEFAULTS = schema_defaults("verification")

WARM_STARTS = ("network", "increment", "previous")


class VerifiedInference:
    """Wrap an inference engine (capped H image -> phi image) with the residual check and
    the local correction of :mod:`ifenn.hybrid.verification` (module doc: the bound, the boxes).

    ``inference``: the network engine (:class:`ifenn.hybrid.process_zone.FullInference` or
    :class:`~ifenn.hybrid.process_zone.ProcessZoneInference`), called every step; with
    ``warm_start="previous"`` it may be None (the network is not used).
    Per call it records ``corrected_fraction`` (share of the image inside correction boxes),
    ``residual_before`` / ``residual_after`` (max |r| over the image before and after the
    correction), ``solve_work`` (CG iterations x box pixels / image pixels: the correction's
    cost in whole-image iterations, independent of the machine's load), ``t_check`` and
    ``t_correction`` (s), ``t_network`` and
    ``evaluated_fraction`` (of the wrapped engine).
    """

    #: correction boxes covering more than this share of the image: one solve on the whole
    #: image instead (its fast transform is exact there; the boxes would cost about as much)
    GLOBAL_FRACTION = 0.5

    def __init__(self, inference, equation: PixelEquation, tolerance: float = VERIFICATION_DEFAULTS["tolerance"],
                 margin_lc: float = VERIFICATION_DEFAULTS["margin_lc"], max_rounds: int = VERIFICATION_DEFAULTS["max_rounds"],
                 solve_fraction: float = VERIFICATION_DEFAULTS["solve_fraction"], warm_start: str = VERIFICATION_DEFAULTS["warm_start"],
                 history_cap: float | None = None, cap_history: bool = VERIFICATION_DEFAULTS["cap_history"]):
        if warm_start not in WARM_STARTS:
            raise ValueError(f"verification warm_start must be one of {WARM_STARTS}, got {warm_start!r}")
        if warm_start != "previous" and inference is None:
            raise ValueError("verification warm_start 'network' needs a network")
        if not tolerance > 0:
            raise ValueError(f"verification tolerance must be > 0, got {tolerance}")
        self.inference, self.equation, self.tolerance = inference, equation, float(tolerance)
        # the margin in pixels: a box's new values meet the old ones at its edge, where the
        # Laplacian turns a jump delta into |r| ~ (Gc lc / h^2) / (Gc / lc) delta = (lc/h)^2 delta; the change
        # of phi decays as exp(-d / lc), so after margin_lc lengths the jump is exp(-margin_lc) x the change
        self.margin = int(np.ceil(float(margin_lc) * equation.lc / equation.h_px))
        self.max_rounds, self.solve_fraction = int(max_rounds), float(solve_fraction)
        self.warm_start = warm_start
        # the network sees H capped at history_cap; the equation too (cap_history, the published step)
        # or H itself (FEM's equation). None: the caller caps (the history it passes is the equation's)
        self.history_cap = None if history_cap is None else float(history_cap)
        self.cap_history = bool(cap_history)
        self.failing_fraction = 0.0
        self.kernel = getattr(inference, "kernel", "")
        self.phi = None           # last verified phi image
        self.residual = None      # its normalised residual
        self.history = None       # the H of the equation it was verified for
        self.prediction = None    # the network's last prediction (a copy)
        self.t_network = self.t_check = self.t_correction = 0.0
        self.evaluated_fraction = self.corrected_fraction = 0.0
        self.residual_before = self.residual_after = 0.0
        self.solve_iterations, self.solve_work = 0, 0.0

    def start_from(self, phi: np.ndarray) -> None:
        """The phase field the run continues from (the FEM state at the switch-over): the
        'previous' warm start of the first step. The first call checks the whole image."""
        if self.phi is None:
            self.phi = np.array(phi, dtype=np.float64)

    def _candidate(self, capped: np.ndarray, history: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The warm start (the network sees ``capped``; ``history``: the equation's H) and the mask
        of pixels whose phi changed since the last verified phi (None: check the whole image)."""
        if self.warm_start == "previous":
            self.t_network, self.evaluated_fraction = 0.0, 0.0
            if self.phi is None:  # nothing to continue from: the local solution 2H / (Gc/lc + 2H)
                return self.equation.local_solution(history), None
            return self.phi.copy(), np.zeros(capped.shape, bool)
        prediction = np.asarray(self.inference(capped), dtype=np.float64)
        self.t_network, self.evaluated_fraction = self.inference.t_network, self.inference.evaluated_fraction
        if self.prediction is None or self.phi is None or self.residual is None:
            self.prediction = prediction.copy()
            return prediction.copy(), None
        # where the prediction did not change, the verified (corrected) phi stays
        changed = prediction != self.prediction
        candidate = self.phi.copy()
        if self.warm_start == "increment":  # the network's change added to the verified phi
            candidate[changed] += prediction[changed] - self.prediction[changed]
        else:
            candidate[changed] = prediction[changed]
        self.prediction[changed] = prediction[changed]
        return candidate, changed

    def __call__(self, history: np.ndarray) -> np.ndarray:
        """The verified phi of a history image (N/mm^2, >= 0): capped at ``history_cap`` for the
        network, and for the equation too unless ``cap_history`` is false."""
        history = np.asarray(history, dtype=np.float64)
        network_input = history if self.history_cap is None else np.minimum(history, self.history_cap)
        if self.cap_history:
            history = network_input
        phi, changed_phi = self._candidate(network_input, history)
        started = time.perf_counter()
        if changed_phi is None or self.residual is None or self.residual.shape != history.shape:
            residual = self.equation.residual_on(phi, history, (slice(0, history.shape[0]), slice(0, history.shape[1])))
        else:
            # the residual changes only where H or phi (within one pixel) changed
            stale = changed_phi | (history != self.history)
            residual = self.residual
            box = bounding_box(stale, 1)
            if box is not None:  # one pass over the changes' bounding box (grown by the stencil)
                residual[box] = self.equation.residual_on(phi, history, box)
        failing = np.abs(residual) > self.tolerance
        self.residual_before = float(np.max(np.abs(residual), initial=0.0))
        self.failing_fraction = float(np.count_nonzero(failing)) / failing.size
        self.t_check = time.perf_counter() - started
        started = time.perf_counter()
        corrected = np.zeros(history.shape, bool)
        self.solve_iterations = 0
        self.solve_work = 0.0   # CG iterations x box pixels / image pixels: a load-independent cost
        margin = self.margin
        for _ in range(self.max_rounds):
            if not failing.any():
                break
            boxes = correction_boxes(failing, margin)
            if sum(box_area(box) for box in boxes) > self.GLOBAL_FRACTION * failing.size:
                boxes = [(slice(0, failing.shape[0]), slice(0, failing.shape[1]))]
            for box in boxes:
                _, iterations = self.equation.solve_box(phi, history, box, self.solve_fraction * self.tolerance)
                self.solve_iterations += iterations
                self.solve_work += iterations * box_area(box) / history.size
                corrected[box] = True
                around = grow_box(box, 1, history.shape)
                residual[around] = self.equation.residual_on(phi, history, around)
            failing = np.abs(residual) > self.tolerance
            log.debug("correction round: %d boxes over %.3f of the image, %d pixels still failing",
                      len(boxes), sum(box_area(b) for b in boxes) / failing.size, int(np.count_nonzero(failing)))
            margin *= 2
        self.residual_after = float(np.max(np.abs(residual), initial=0.0))
        self.corrected_fraction = float(np.count_nonzero(corrected)) / corrected.size
        self.t_correction = time.perf_counter() - started
        self.phi, self.residual, self.history = phi, residual, history.copy()
        return phi
