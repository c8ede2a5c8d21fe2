"""Inference of the pixel phase field: the whole image every step (the paper), or only the
process zone (issue 5).

Both engines map the capped history image H_c (ny, nx) to the smoothed prediction
phi = G_sigma * N(H_c), where N is a local operator (the PICNN: an output pixel depends on
the inputs within ``r_net`` pixels, a square window, 8 for the default network) and G_sigma
the Gaussian filter (radius ``r_s = round(truncate sigma)``, 8 at sigma 2).

Process-zone inference keeps the last network output and smoothed image and, after one
full evaluation, re-evaluates only boxes around the pixels whose network input changed:
an output of N can only change within r_net of a changed input, so N is evaluated on the
bounding boxes of the connected components of (changed pixels grown by r_net), each from
its inputs within r_net (an evaluator's ``predict_box``: exact wherever the box lies, the
image edge's padding included). The filter is linear and local, so the smoothed image
changes only within r_s of those boxes and is recomputed there from the stored network
output. With ``tolerance = 0`` this reproduces full inference to round-off.

Error bound. Changes are measured in the units of the output: the local phase field
phi_loc = 2 H_c / (Gc/lc + 2 H_c), the solution of the pixel equation for uniform H, which
the network reproduces where H varies slowly; it is insensitive to H far below Gc/(2 lc)
(the far field) and above it (the crack). A pixel counts as changed once its phi_loc moved
by more than ``tolerance`` from its reference, the value it had when every output that
depends on it was last recomputed (pixels read but not reset keep their older reference, so
they were within ``tolerance`` of it when read). Hence every input
behind every stored output differs from the current one by at most 2 x tolerance in phi_loc,
at every step (inputs that drift further are re-evaluated that step); for the exact pixel
equation, whose solution operator is monotone, the stored phi is then within about
2 x tolerance of the current one. ``refresh_every`` re-evaluates the whole image as a guard,
and when the boxes would cover more than ``full_fraction`` of the image the whole image is
evaluated instead (it is then cheaper).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.ndimage

from .pixels import Box, box_area, box_within, grow_box


def _smoothing_radius(sigma: float | None, truncate: float) -> int:
    # scipy.ndimage.gaussian_filter's kernel radius
    return int(truncate * float(sigma) + 0.5) if sigma else 0


def _smooth(image: np.ndarray, sigma: float | None, truncate: float) -> np.ndarray:
    from .picnn import gaussian_smoothing

    return gaussian_smoothing(image, sigma, truncate) if sigma else image


class FullInference:
    """The paper's step: evaluate ``predictor`` on the whole image, then smooth it."""

    name = "full"

    def __init__(self, predictor, sigma: float | None, truncate: float = 4.0):
        self.predictor, self.sigma, self.truncate = predictor, sigma, truncate
        self.t_network = 0.0
        self.evaluated_fraction = 1.0

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        raw = self.predictor(capped)
        self.t_network = time.perf_counter() - started
        return _smooth(raw, self.sigma, self.truncate)


class ProcessZoneInference:
    """Evaluate a local network only in boxes around pixels whose input changed.

    ``evaluator``: a PICNN evaluator (:mod:`ifenn.orbit`: ``predict``, ``predict_box``,
    ``receptive_radius``).
    """

    name = "process_zone"

    def __init__(self, evaluator, sigma: float | None, truncate: float = 4.0, tolerance: float = 1e-3,
                 refresh_every: int = 100, full_fraction: float = 0.3, local_scale: float = 90.0):
        if not hasattr(evaluator, "predict_box"):
            raise ValueError("process-zone inference needs a local predictor (the PICNN), not a global pixel solve")
        self.evaluator, self.sigma, self.truncate = evaluator, sigma, truncate
        self.tolerance, self.refresh_every, self.full_fraction = tolerance, refresh_every, full_fraction
        self.local_scale = local_scale  # Gc / lc, N/mm^2
        self.r_net = int(evaluator.receptive_radius)
        self.r_s = _smoothing_radius(sigma, truncate)
        self.reference = None   # phi_loc of each pixel's input when its drift last restarted
        self.raw = None         # stored network output
        self.smoothed = None    # stored smoothed output
        self.steps_since_full = 0
        self.t_network = 0.0
        self.evaluated_fraction = 0.0

    def local_phase_field(self, capped: np.ndarray) -> np.ndarray:
        """phi_loc = 2 H_c / (Gc/lc + 2 H_c): what the change of a pixel is measured in."""
        return 2.0 * capped / (self.local_scale + 2.0 * capped)

    def _history_at(self, phi_loc: np.ndarray) -> np.ndarray:
        """The inverse of phi_loc: H = (Gc/lc) phi / (2 (1 - phi)); +inf from phi = 1 on, -inf from 0 down."""
        with np.errstate(divide="ignore", invalid="ignore"):
            history = self.local_scale * phi_loc / (2.0 * (1.0 - phi_loc))
        return np.where(phi_loc >= 1.0, np.inf, np.where(phi_loc <= 0.0, -np.inf, history))

    def _set_reference(self, capped: np.ndarray, where=None, mask=None) -> None:
        """Restart the drift of the pixels ``where`` (and ``mask`` within it): reference phi_loc
        and the H interval within which phi_loc stays within the tolerance of it."""
        where = (slice(None), slice(None)) if where is None else where
        current = capped[where]
        local = self.local_phase_field(current)
        # the current value always lies inside its interval (round-off of the inverse aside)
        upper = np.maximum(self._history_at(local + self.tolerance), current)
        lower = np.minimum(self._history_at(local - self.tolerance), current)
        if mask is not None:
            local, upper, lower = (np.where(mask, new, old[where]) for new, old in
                                   ((local, self.reference), (upper, self.upper), (lower, self.lower)))
        self.reference[where], self.upper[where], self.lower[where] = local, upper, lower

    def _full(self, capped: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        self.raw = self.evaluator.predict(capped)
        self.t_network = time.perf_counter() - started
        self.smoothed = _smooth(self.raw, self.sigma, self.truncate)
        self.reference, self.upper, self.lower = (np.empty_like(capped, dtype=float) for _ in range(3))
        self._set_reference(capped)
        self.steps_since_full = 0
        self.evaluated_fraction = 1.0
        return self.smoothed

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        if self.raw is None or self.raw.shape != capped.shape or self.steps_since_full + 1 >= self.refresh_every:
            return self._full(capped)
        self.steps_since_full += 1
        # |phi_loc - reference| > tolerance, as H outside the interval (phi_loc is monotone)
        changed = (capped > self.upper) | (capped < self.lower)
        self.t_network, self.evaluated_fraction = 0.0, 0.0
        rows, cols = np.nonzero(changed)
        if rows.size == 0:
            return self.smoothed
        ny, nx = capped.shape
        R = self.r_net
        # The outputs that can change: the changed pixels grown by R (a square, the receptive
        # field of the convolutions). Group the changed pixels on blocks of R pixels (pixels
        # whose squares overlap or nearly so end up together); each group's box is the bounding
        # box of its pixels grown by R, split where that saves work (_split).
        block = max(R, 1)
        coarse = np.zeros((-(-ny // block), -(-nx // block)), dtype=bool)
        coarse[rows // block, cols // block] = True
        labels, n_groups = scipy.ndimage.label(scipy.ndimage.maximum_filter(coarse, size=5), structure=np.ones((3, 3), int))
        group_of = labels[rows // block, cols // block]
        components = []
        for group in range(1, n_groups + 1):
            members = group_of == group
            if members.any():
                r, c = rows[members], cols[members]
                components.append(grow_box((slice(r.min(), r.max() + 1), slice(c.min(), c.max() + 1)), R, (ny, nx)))
        parts = [_split(changed, component, R) for component in components]
        evaluated = sum(box_area(grow_box(box, R, (ny, nx))) for boxes in parts for box in boxes)  # inputs read
        if evaluated > self.full_fraction * ny * nx:
            return self._full(capped)
        started = time.perf_counter()
        for boxes in parts:
            for box in boxes:
                self.raw[box] = self.evaluator.predict_box(capped, box)
        self.t_network = time.perf_counter() - started
        self.evaluated_fraction = evaluated / (ny * nx)
        for component, boxes in zip(components, parts, strict=True):
            # every output that depends on an input covered by the boxes was just computed from
            # its current value: those inputs restart their drift (outside the image counts as covered)
            region = grow_box(component, R, (ny, nx))
            covered = np.zeros((region[0].stop - region[0].start, region[1].stop - region[1].start), dtype=bool)
            for box in boxes:
                covered[box_within(box, region)] = True
            on_edge = ((region[0].start == 0, region[0].stop == ny), (region[1].start == 0, region[1].stop == nx))
            fresh = scipy.ndimage.minimum_filter(np.pad(covered, R, constant_values=on_edge), size=2 * R + 1)[R:-R, R:-R]
            self._set_reference(capped, region, fresh)
            # the filter is linear and local: the smoothed image changes within r_s of the boxes
            if self.sigma:
                out = grow_box(component, self.r_s, (ny, nx))
                support = grow_box(out, self.r_s, (ny, nx))
                self.smoothed[out] = _smooth(self.raw[support], self.sigma, self.truncate)[box_within(out, support)]
            else:
                self.smoothed[component] = self.raw[component]
        return self.smoothed


def _split(mask: np.ndarray, box: Box, margin: int, depth: int = 6) -> list[Box]:
    """Cover the pixels within ``margin`` of a True pixel of ``mask`` in ``box`` by boxes: the
    box itself, or, where that costs less, the tight boxes of its two halves (split across the
    longer side), recursively. Cost of a box: its area grown by ``margin`` (what the network
    reads for it)."""
    def cost(b):
        return (b[0].stop - b[0].start + 2 * margin) * (b[1].stop - b[1].start + 2 * margin)

    ny, nx = mask.shape

    def tight(b):
        # bounding box of (changed pixels grown by margin) within b: the changed pixels in b
        # grown by margin, their bounding box grown by margin, clipped to b
        around = grow_box(b, margin, (ny, nx))
        sub = mask[around]
        rows, cols = np.flatnonzero(sub.any(axis=1)), np.flatnonzero(sub.any(axis=0))
        if rows.size == 0:
            return None
        return (slice(max(around[0].start + rows[0] - margin, b[0].start), min(around[0].start + rows[-1] + 1 + margin, b[0].stop)),
                slice(max(around[1].start + cols[0] - margin, b[1].start), min(around[1].start + cols[-1] + 1 + margin, b[1].stop)))

    box = tight(box)
    if box is None:
        return []
    height, width = box[0].stop - box[0].start, box[1].stop - box[1].start
    if depth == 0 or max(height, width) < 4 * margin:
        return [box]
    axis = 0 if height >= width else 1
    middle = box[axis].start + (box[axis].stop - box[axis].start) // 2
    halves = [list(box), list(box)]
    halves[0][axis], halves[1][axis] = slice(box[axis].start, middle), slice(middle, box[axis].stop)
    parts = [t for t in (tight(tuple(h)) for h in halves) if t is not None]
    if sum(cost(p) for p in parts) >= 0.9 * cost(box):
        return [box]
    return [b for part in parts for b in _split(mask, part, margin, depth - 1)]
