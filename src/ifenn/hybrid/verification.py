"""Verified phase-field step: every prediction checked by the pixel equation it was trained
on, and corrected where it fails.

The pixel equation (the PICNN's physics loss, :func:`ifenn.network.picnn.residual`) at pixel i:

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
import scipy.fft
import scipy.ndimage

from ifenn.errors import SolverDivergedError
from ifenn.pixels import LAPLACIAN_K9_STAR, Box, SlitCuts, box_area, grow_box
from ifenn.schema import schema_defaults

log = logging.getLogger(__name__)

#: the settings' defaults: those of the config schema ('ifenn.verification')
_DEFAULTS = schema_defaults("verification")


def _kernel():
    from ifenn.network.orbit_kernel import load

    return load()

WARM_STARTS = ("network", "increment", "previous")


def _stencil_sum(padded: np.ndarray) -> np.ndarray:
    """K9*(x) of the interior of a once-padded array (n + 2, m + 2) -> (n, m)."""
    edge = padded[1:-1, :-2] + padded[1:-1, 2:] + padded[:-2, 1:-1] + padded[2:, 1:-1]
    corner = padded[:-2, :-2] + padded[:-2, 2:] + padded[2:, :-2] + padded[2:, 2:]
    return LAPLACIAN_K9_STAR[0, 1] * edge + LAPLACIAN_K9_STAR[0, 0] * corner


def normalised_residual(phi, history, Gc, lc, h_px, padding="replicate", cuts: SlitCuts | None = None) -> np.ndarray:
    """r = R / (Gc/lc + 2H) on the whole image: an upper bound, in the max norm, of
    |phi - exact| (module doc). R is the residual of :func:`ifenn.network.picnn.residual`,
    with the stencil links that ``cuts`` (the scene's slits) cut left out."""
    phi, history = np.asarray(phi, dtype=np.float64), np.asarray(history, dtype=np.float64)
    return PixelEquation(Gc, lc, h_px, padding, cuts).residual_on(phi, history, (slice(0, phi.shape[0]), slice(0, phi.shape[1])))


class PixelEquation:
    """The pixel equation of one image: residuals and local solves on boxes. ``cuts``: the
    stencil links the scene's slits cut (:class:`ifenn.pixels.SlitCuts`; None: no slit)."""

    def __init__(self, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts: SlitCuts | None = None):
        if padding not in ("replicate", "zeros"):
            raise ValueError(f"pixel equation padding must be 'replicate' or 'zeros', got {padding!r}")
        self.Gc, self.lc, self.h_px, self.padding = Gc, lc, h_px, padding
        self.cuts = cuts if cuts else None
        self._coarse_cache: dict = {}   # box -> the coarse levels' cut links (_level_links)
        self.diffusion = Gc * lc / h_px**2
        self.reaction0 = Gc / lc

    def _extended(self, phi: np.ndarray, box: Box) -> np.ndarray:
        """phi on ``box`` with a one-pixel frame: image values where the box is inside, the
        padding where it meets the image edge (float64, contiguous)."""
        (r0, r1), (c0, c1) = (box[0].start, box[0].stop), (box[1].start, box[1].stop)
        ny, nx = phi.shape
        inner = phi[max(r0 - 1, 0):min(r1 + 1, ny), max(c0 - 1, 0):min(c1 + 1, nx)]
        widths = ((int(r0 == 0), int(r1 == ny)), (int(c0 == 0), int(c1 == nx)))
        if not any(any(w) for w in widths):
            return np.array(inner, dtype=np.float64)
        return np.pad(inner.astype(np.float64, copy=False), widths, mode="edge" if self.padding == "replicate" else "constant")

    def _operator(self, ext: np.ndarray, history: np.ndarray, with_rhs: bool) -> np.ndarray:
        """(a c - D (K9*(c) - 3 c) [- 2 H]) for the centre c of ``ext``, a = Gc/lc + 2 H, in numpy
        (the fallback of the compiled residual and correction)."""
        centre = ext[1:-1, 1:-1]
        out = (self.reaction0 + 2.0 * history) * centre - self.diffusion * (_stencil_sum(ext) - 3.0 * centre)
        return out - 2.0 * history if with_rhs else out

    def residual_on(self, phi: np.ndarray, history: np.ndarray, box: Box, normalised: bool = True) -> np.ndarray:
        """Residual on ``box`` (its own shape): r = R / (Gc/lc + 2H), or R itself; in one pass of
        the compiled kernel where it builds (read from the image: no padded copy), else in numpy;
        the slits' cut links are then taken out (R += D x their flux)."""
        if self.cuts is None:
            return self._residual_uncut(phi, history, box, normalised)
        residual = self._residual_uncut(phi, history, box, False) + self.diffusion * self.cuts.flux_on(phi, box)
        return residual / (self.reaction0 + 2.0 * history[box]) if normalised else residual

    def _residual_uncut(self, phi: np.ndarray, history: np.ndarray, box: Box, normalised: bool) -> np.ndarray:
        lib = _kernel()
        if lib is not None:
            phi, history = np.ascontiguousarray(phi, dtype=np.float64), np.ascontiguousarray(history, dtype=np.float64)
            ny, nx = phi.shape
            out = np.empty((box[0].stop - box[0].start, box[1].stop - box[1].start))
            lib.ifenn_pixel_residual(phi.ctypes.data, history.ctypes.data, out.ctypes.data, ny, nx, box[0].start, box[0].stop,
                                     box[1].start, box[1].stop, self.reaction0, self.diffusion, int(self.padding == "replicate"),
                                     int(normalised))
            return out
        h = history[box]
        residual = self._operator(self._extended(phi, box), h, True)
        return residual / (self.reaction0 + 2.0 * h) if normalised else residual

    def _apply(self, x: np.ndarray, history: np.ndarray, edges: tuple[bool, bool, bool, bool], links=None) -> np.ndarray:
        """A x on a box (``history``: H there) for x with zero Dirichlet data around it (the
        padding on image edges); ``links``: the slits' cut links in the box (SlitCuts.in_box)."""
        out = self._apply_uncut(x, history, edges)
        if links is not None and links[0].size:
            rows, cols, weights = links
            flat = x.reshape(-1)
            np.add.at(out.reshape(-1), rows, self.diffusion * weights * (np.where(cols >= 0, flat[np.maximum(cols, 0)], 0.0) - flat[rows]))
        return out

    def _apply_uncut(self, x: np.ndarray, history: np.ndarray, edges: tuple[bool, bool, bool, bool]) -> np.ndarray:
        ext = np.zeros((x.shape[0] + 2, x.shape[1] + 2))
        ext[1:-1, 1:-1] = x
        if self.padding == "replicate":
            bottom, top, left, right = edges
            if bottom:
                ext[0, 1:-1] = x[0]
            if top:
                ext[-1, 1:-1] = x[-1]
            if left:
                ext[:, 0] = ext[:, 1]
            if right:
                ext[:, -1] = ext[:, -2]
        return self._operator(ext, history, False)

    def _preconditioner(self, box: Box, shape: tuple[int, int], reaction: np.ndarray):
        """The exact inverse of the constant-coefficient operator min(a) I - D (K9* - 3 I) on
        the box, by a fast sine transform (zero Dirichlet data around the box: exact there) or,
        for the whole image, by the image padding's own transform (as the global pixel solver)."""
        from ifenn.network.picnn import _fast_transforms, _laplacian_symbol

        n, m = box[0].stop - box[0].start, box[1].stop - box[1].start
        if (n, m) == tuple(shape):
            symbol = reaction.min() - self.diffusion * _laplacian_symbol(n, m, self.padding)
            forward, inverse = _fast_transforms(self.padding)
            return lambda r: inverse(forward(r) / symbol)
        s_y = 2.0 * np.cos(np.pi * np.arange(1, n + 1) / (n + 1))[:, None]
        s_x = 2.0 * np.cos(np.pi * np.arange(1, m + 1) / (m + 1))[None, :]
        symbol = reaction.min() - self.diffusion * (0.5 * (s_x + s_y) + 0.25 * s_x * s_y - 3.0)
        return lambda r: scipy.fft.dstn(scipy.fft.dstn(r, type=1, norm="ortho") / symbol, type=1, norm="ortho")

    def _level_links(self, box: Box, links) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cut links of every multigrid level of ``box`` for the compiled V-cycle: per level
        the count, then rows / cols / weights one level after another (the finest: ``links``, the
        box's own; the coarser: the slits redrawn at each level's spacing, cached per box). The
        levels halve as the kernel's (``mg_work``): while both sides exceed 4, at most 16."""
        if links is None:
            return np.zeros(0, np.intc), np.zeros(0, np.intc), np.zeros(0, np.intc), np.zeros(0)
        key = (box[0].start, box[0].stop, box[1].start, box[1].stop)
        cache = self._coarse_cache
        if key not in cache:
            shape, levels = (box[0].stop - box[0].start, box[1].stop - box[1].start), []
            while shape[0] > 4 and shape[1] > 4 and len(levels) < 15:
                shape = ((shape[0] + 1) // 2, (shape[1] + 1) // 2)
                levels.append(self.cuts.coarse_links(box, len(levels) + 1, shape))
            if len(cache) > 64:
                cache.clear()
            cache[key] = levels
        parts = [links, *cache[key]]
        counts = np.array([len(p[0]) for p in parts], dtype=np.intc)
        return (counts, np.ascontiguousarray(np.concatenate([p[0] for p in parts]), dtype=np.intc),
                np.ascontiguousarray(np.concatenate([p[1] for p in parts]), dtype=np.intc),
                np.ascontiguousarray(np.concatenate([p[2] for p in parts]), dtype=np.float64))

    def solve_box(self, phi: np.ndarray, history: np.ndarray, box: Box, target: float, maxiter: int = 1000) -> tuple[float, int]:
        """Solve the pixel equation on ``box`` in place in ``phi`` (the values around the box
        fixed), to max |r| <= ``target`` inside it, by conjugate gradients preconditioned with a
        multigrid V-cycle (compiled kernel), else with the constant-coefficient inverse
        (:meth:`_preconditioner`). Returns (max |r| reached, iterations); raises if ``maxiter``
        iterations do not get there."""
        ny, nx = phi.shape
        edges = (box[0].start == 0, box[0].stop == ny, box[1].start == 0, box[1].stop == nx)
        h = np.ascontiguousarray(history[box])
        reaction = self.reaction0 + 2.0 * h
        links = self.cuts.in_box(box) if self.cuts is not None else None
        lib = _kernel()
        if lib is not None:  # multigrid-preconditioned CG, compiled
            # the correction delta solves A delta = -R(phi), zero around the box
            residual = -self.residual_on(phi, history, box, normalised=False)
            centre = phi[box]
            delta = np.empty(centre.shape)
            replicate = np.array(edges if self.padding == "replicate" else (False,) * 4, dtype=np.intc)
            worst = np.zeros(1)
            counts, rows, cols, weights = self._level_links(box, links)
            iterations = lib.ifenn_pixel_mg_pcg(residual.ctypes.data, np.ascontiguousarray(reaction).ctypes.data, delta.ctypes.data,
                                                delta.shape[0], delta.shape[1], self.diffusion, replicate.ctypes.data, target, maxiter,
                                                worst.ctypes.data, counts.size, counts.ctypes.data, rows.ctypes.data, cols.ctypes.data,
                                                weights.ctypes.data)
            if iterations < 0:
                raise SolverDivergedError(f"pixel correction on {box} did not reach max |r| = {target:g} in {maxiter} iterations "
                                   f"(reached {worst[0]:g})")
            phi[box] += delta
            return float(worst[0]), int(iterations)
        ext = self._extended(phi, box)
        centre = ext[1:-1, 1:-1]
        residual = -self.residual_on(phi, history, box, normalised=False)
        worst = float(np.max(np.abs(residual) / reaction))
        iterations = 0
        delta = np.zeros_like(centre)
        if worst > target:
            precondition = self._preconditioner(box, phi.shape, reaction)
            z = precondition(residual)
            direction = z.copy()
            rz = float(np.vdot(residual, z))
            while True:
                if iterations == maxiter:
                    raise SolverDivergedError(f"pixel correction on {box} did not reach max |r| = {target:g} in {maxiter} iterations "
                                       f"(reached {worst:g})")
                iterations += 1
                a_dir = self._apply(direction, h, edges, links)
                alpha = rz / float(np.vdot(direction, a_dir))
                delta += alpha * direction
                residual -= alpha * a_dir
                worst = float(np.max(np.abs(residual) / reaction))
                if worst <= target:
                    break
                z = precondition(residual)
                rz_new = float(np.vdot(residual, z))
                direction = z + (rz_new / rz) * direction
                rz = rz_new
        phi[box] = centre + delta
        return worst, iterations


def _bounding_box(mask: np.ndarray, grow: int) -> Box | None:
    """The bounding box of ``mask``'s pixels grown by ``grow`` (clipped), None if empty."""
    rows, cols = np.nonzero(np.any(mask, axis=1))[0], np.nonzero(np.any(mask, axis=0))[0]
    if rows.size == 0:
        return None
    return grow_box((slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)), grow, mask.shape)


def dilated(mask: np.ndarray, by: int) -> np.ndarray:
    """``mask`` grown by ``by`` pixels (square), computed on its bounding box only."""
    crop = _bounding_box(mask, by)
    out = np.zeros_like(mask)
    if crop is not None and by > 0:  # a square's maximum filter is separable: O(pixels), whatever ``by``
        out[crop] = scipy.ndimage.maximum_filter(mask[crop].view(np.uint8), size=2 * by + 1, mode="constant") > 0
    elif crop is not None:
        out[crop] = mask[crop]
    return out


def _boxes(mask: np.ndarray, margin: int) -> list[Box]:
    """Bounding boxes of the connected groups of ``mask`` grown by at least ``margin`` pixels;
    boxes that overlap are merged.

    Computed on blocks of b = margin // 8 pixels (b = 1 for small margins): a block is set
    where any of its pixels is, the blocks are grown by ceil(margin / b) and grouped, and each
    group's box is taken back to pixels. Every pixel within ``margin`` of a set pixel lies in
    a box (the boxes exceed the exact ones by less than 2 b on each side), at 1 / b^2 of the
    cost: the dilation of a large mask by a margin of 6 lc otherwise costs about as much as a
    multigrid iteration of the correction."""
    crop = _bounding_box(mask, margin)
    if crop is None:
        return []
    block = max(1, margin // 8)
    sub = mask[crop]
    if block > 1:
        ny, nx = -(-sub.shape[0] // block), -(-sub.shape[1] // block)
        padded = np.zeros((ny * block, nx * block), bool)
        padded[:sub.shape[0], :sub.shape[1]] = sub
        sub = padded.reshape(ny, block, nx, block).any(axis=(1, 3))
    grown = dilated(sub, -(-margin // block))
    labels, _ = scipy.ndimage.label(grown, structure=np.ones((3, 3), int))
    shape = mask.shape
    boxes = [tuple(slice(min(c.start + s.start * block, n), min(c.start + s.stop * block, c.stop, n))
                   for s, c, n in zip(b, crop, shape, strict=True))
             for b in scipy.ndimage.find_objects(labels) if b is not None]
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if all(s.start < t.stop and t.start < s.stop for s, t in zip(a, b, strict=True)):
                    boxes[i] = tuple(slice(min(s.start, t.start), max(s.stop, t.stop)) for s, t in zip(a, b, strict=True))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return boxes


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

    def __init__(self, inference, equation: PixelEquation, tolerance: float = _DEFAULTS["tolerance"],
                 margin_lc: float = _DEFAULTS["margin_lc"], max_rounds: int = _DEFAULTS["max_rounds"],
                 solve_fraction: float = _DEFAULTS["solve_fraction"], warm_start: str = _DEFAULTS["warm_start"],
                 history_cap: float | None = None, cap_history: bool = _DEFAULTS["cap_history"]):
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
                return 2.0 * history / (self.equation.reaction0 + 2.0 * history), None
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
            box = _bounding_box(stale, 1)
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
            boxes = _boxes(failing, margin)
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
