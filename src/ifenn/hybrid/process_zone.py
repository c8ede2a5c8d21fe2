"""Inference of the pixel phase field: the whole image every step (the paper), or only the
process zone.

Both engines map the capped history image H_c (ny, nx) to the smoothed prediction
phi = G_sigma * N(H_c), where N is a local operator (the PICNN: an output pixel depends on
the inputs within ``r_net`` pixels, a square window, 8 for the default network) and G_sigma
the Gaussian filter (radius ``r_s = round(truncate sigma)``, 8 at sigma 2).

Process-zone inference keeps every layer's activations of the last evaluation
(:class:`ifenn.network.orbit.NetworkState`) and, after one full evaluation, rewrites only the inputs
within r_net of pixels whose capped H changed (r_net = (layers) r, the network's reach, 8 for
the default network; rewriting only the changed pixels themselves left their neighbours,
drifting just under the tolerance, stale next to the crack tip) and recomputes what depends on
them: layer 1 within the kernel radius r of those pixels, layer 2 within r of that, and so on,
so the output within r_net of them. The changed pixels are grouped into crops that lie more
than 4 r_net apart, carried through the layers one crop at a time. The filter is linear and local, so the smoothed image changes only
within r_s of the recomputed outputs and is recomputed there from the stored network
output. With ``tolerance = 0`` this reproduces full inference to round-off.

Error bound. Changes are measured in the units of the output: the local phase field
phi_loc = 2 H_c / (Gc/lc + 2 H_c), the solution of the pixel equation for uniform H, which
the network reproduces where H varies slowly; it is insensitive to H far below Gc/(2 lc)
(the far field) and above it (the crack). A pixel counts as changed once its phi_loc moved
by more than ``tolerance`` from its reference, the value it had when its input was last
rewritten (then every activation that depends on it was recomputed from the new value; a
pixel not rewritten keeps its older input, which is within ``tolerance`` of its reference).
Hence every input behind every stored output differs from the current one by at most
2 x tolerance in phi_loc, at every step (inputs that drift further are re-evaluated that step); for the exact pixel
equation, whose solution operator is monotone, the stored phi is then within about
2 x tolerance of the current one. ``refresh_every`` re-evaluates the whole image as a guard,
and when the crops would cover more than ``full_fraction`` of the image the whole image is
evaluated instead (it is then cheaper).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.ndimage

from ifenn.pixels import box_area, box_within, grow_box
from ifenn.schema import schema_defaults

#: the settings' defaults: those of the config schema ('ifenn.process_zone')
PROCESS_ZONE_DEFAULTS = schema_defaults("process_zone")


def _smoothing_radius(sigma: float | None, truncate: float) -> int:
    # scipy.ndimage.gaussian_filter's kernel radius
    return int(truncate * float(sigma) + 0.5) if sigma else 0


def _smooth(image: np.ndarray, sigma: float | None, truncate: float) -> np.ndarray:
    from ifenn.pixel_equation.numpy_backend import gaussian_smoothing

    return gaussian_smoothing(image, sigma, truncate) if sigma else image


class FullInference:
    """The paper's step: evaluate ``predictor`` on the whole image, then smooth it."""

    name = "full"

    def __init__(self, predictor, sigma: float | None, truncate: float = 4.0, kernel: str = ""):
        self.predictor, self.sigma, self.truncate = predictor, sigma, truncate
        self.kernel = kernel   # what evaluates the network, for the record ("" for other predictors)
        self.t_network = 0.0
        self.evaluated_fraction = 1.0

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        raw = self.predictor(capped)
        self.t_network = time.perf_counter() - started
        return _smooth(raw, self.sigma, self.truncate)


class ProcessZoneInference:
    """Carry the changes of the network input through the network only where they reach.

    ``evaluator``: the PICNN's orbit evaluator (:class:`ifenn.network.orbit.OrbitEvaluator`: its
    ``network_state`` and ``receptive_radius``).
    """

    name = "process_zone"

    def __init__(self, evaluator, sigma: float | None, truncate: float = 4.0, tolerance: float = PROCESS_ZONE_DEFAULTS["tolerance"],
                 refresh_every: int = PROCESS_ZONE_DEFAULTS["refresh_every"], full_fraction: float = PROCESS_ZONE_DEFAULTS["full_fraction"],
                 local_scale: float = 90.0, shape: tuple[int, int] | None = None):
        if not hasattr(evaluator, "network_state"):
            raise ValueError("process-zone inference needs the local PICNN in its orbit evaluation (ifenn evaluation: orbit), "
                             "not a global pixel solve or the convolution path")
        if evaluator.padding == "circular":
            raise ValueError("process-zone inference needs a network that pads by zeros, replicate or reflect: 'circular' "
                             "padding makes the pixels at one edge depend on those at the opposite edge")
        self.evaluator, self.sigma, self.truncate = evaluator, sigma, truncate
        self.kernel = evaluator.kernel
        self.tolerance, self.refresh_every, self.full_fraction = tolerance, refresh_every, full_fraction
        self.local_scale = local_scale  # Gc / lc, N/mm^2
        self.r_net = int(evaluator.receptive_radius)
        self.r_s = _smoothing_radius(sigma, truncate)
        self.reference = None   # phi_loc of each pixel's input when its drift last restarted
        # the network's activations, layer by layer (ifenn.network.orbit.NetworkState); allocated here
        # when the image ``shape`` is known, as the FEM step builds its matrix ahead of time
        self.state = None if shape is None else evaluator.network_state(shape)
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

    def _set_reference(self, capped: np.ndarray, where=None) -> None:
        """Restart the drift of the pixels ``where`` (an index of the image): reference phi_loc
        and the H interval within which phi_loc stays within the tolerance of it."""
        where = (slice(None), slice(None)) if where is None else where
        current = capped[where]
        local = self.local_phase_field(current)
        # the current value always lies inside its interval (round-off of the inverse aside)
        upper = np.maximum(self._history_at(local + self.tolerance), current)
        lower = np.minimum(self._history_at(local - self.tolerance), current)
        self.reference[where], self.upper[where], self.lower[where] = local, upper, lower

    def _full(self, capped: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        if self.state is None or self.state.shape != capped.shape:
            self.state = self.evaluator.network_state(capped.shape)
        self.state.full(capped)
        self.t_network = time.perf_counter() - started
        self.smoothed = _smooth(self.raw.astype(np.float64), self.sigma, self.truncate)
        self.reference, self.upper, self.lower = (np.empty_like(capped, dtype=float) for _ in range(3))
        self._set_reference(capped)
        self.steps_since_full = 0
        self.evaluated_fraction = 1.0
        return self.smoothed

    @property
    def raw(self) -> np.ndarray | None:
        """The stored network output (float32)."""
        return None if self.state is None else self.state.output

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        if self.smoothed is None or self.state.shape != capped.shape or self.steps_since_full + 1 >= self.refresh_every:
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
        # Group the changed pixels on blocks of R pixels: groups whose pixels lie within about
        # 5 R of each other end up together, so what one group's change reaches (2 R around it:
        # the inputs rewritten within R, the outputs within R of those) never meets another's and each is carried through the network on its own crop.
        block = max(R, 1)
        coarse = np.zeros((-(-ny // block), -(-nx // block)), dtype=bool)
        coarse[rows // block, cols // block] = True
        labels, n_groups = scipy.ndimage.label(scipy.ndimage.maximum_filter(coarse, size=5), structure=np.ones((3, 3), int))
        group_of = labels[rows // block, cols // block]
        order = np.argsort(group_of, kind="stable")
        bounds = np.searchsorted(group_of[order], np.arange(1, n_groups + 2))
        groups = []
        for g in range(n_groups):
            members = order[bounds[g]:bounds[g + 1]]
            if members.size:
                r, c = rows[members], cols[members]
                groups.append((r, c, grow_box((slice(r.min(), r.max() + 1), slice(c.min(), c.max() + 1)), 2 * R, (ny, nx))))
        if sum(box_area(crop) for _, _, crop in groups) > self.full_fraction * ny * nx:
            return self._full(capped)
        started = time.perf_counter()
        recomputed = 0
        for r, c, crop in groups:
            mask = np.zeros((crop[0].stop - crop[0].start, crop[1].stop - crop[1].start), dtype=bool)
            mask[r - crop[0].start, c - crop[1].start] = True
            # rewrite the inputs within R of each change, not only its own: inputs that drifted
            # just under the tolerance would otherwise stay stale next to the crack tip
            mask = self.evaluator.dilate(mask, R)
            r, c = np.nonzero(mask)
            r, c = r + crop[0].start, c + crop[1].start
            self.state.set_inputs(capped, r, c)
            recomputed += int(np.count_nonzero(self.state.propagate(mask, (crop[0].start, crop[1].start))))
            # every output that depends on a rewritten input was just recomputed from its
            # current value: those inputs restart their drift
            self._set_reference(capped, (r, c))
        self.t_network = time.perf_counter() - started
        self.evaluated_fraction = recomputed / (ny * nx)
        # the filter is linear and local: the smoothed image changes within r_s of the crops
        for _, _, crop in groups:
            if self.sigma:
                out = grow_box(crop, self.r_s, (ny, nx))
                support = grow_box(out, self.r_s, (ny, nx))
                self.smoothed[out] = _smooth(self.raw[support].astype(np.float64), self.sigma, self.truncate)[box_within(out, support)]
            else:
                self.smoothed[crop] = self.raw[crop]
        return self.smoothed


