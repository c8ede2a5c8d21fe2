"""Inference of the pixel phase field: the whole image every step (the paper), or only the
process zone (issue 5).

Both engines map the capped history image H_c (ny, nx) to the smoothed prediction
phi = G_sigma * N(H_c), where N is a local operator (the PICNN: an output pixel depends on
the inputs within ``r_net`` pixels, a square window, 8 for the default network) and G_sigma
the Gaussian filter (radius ``r_s = round(truncate sigma)``, 8 at sigma 2).

Process-zone inference keeps the last network output and smoothed image and, after one
full evaluation, re-evaluates only windows around the pixels whose network input changed:
an output of N can only change within r_net of a changed input, the smoothed image within
r_net + r_s. Each window is evaluated on a crop with r_net (network) and r_s (filter) more
pixels of context, clipped at the image edge, where the crop's padding equals the full
image's; so with ``tolerance = 0`` the windows reproduce full inference to round-off.

Error bound. Changes are measured in the units of the output: the local phase field
phi_loc = 2 H_c / (Gc/lc + 2 H_c), the solution of the pixel equation for uniform H, which
the network reproduces where H varies slowly; it is insensitive to H far below Gc/(2 lc)
(the far field) and above it (the crack). A pixel counts as changed once its phi_loc moved
by more than ``tolerance`` from the value it had when it was last marked. Hence every input
behind every stored output differs from the current one by at most 2 x tolerance in phi_loc,
at every step (inputs that drift further are re-evaluated that step); for the exact pixel
equation, whose solution operator is monotone, the stored phi is then within about
2 x tolerance of the current one. ``refresh_every`` re-evaluates the whole image as a guard,
and when the windows would cover more than ``full_fraction`` of the image the whole image is
evaluated instead (it is then cheaper).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.ndimage


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
    """Evaluate a local network only in windows around pixels whose input changed.

    ``model``: a PICNN (``predict``, ``network_input``, ``receptive_radius``).
    """

    name = "process_zone"

    def __init__(self, model, sigma: float | None, truncate: float = 4.0, tolerance: float = 1e-3,
                 refresh_every: int = 100, full_fraction: float = 0.3, local_scale: float = 90.0):
        if not hasattr(model, "receptive_radius"):
            raise ValueError("process-zone inference needs a local predictor (the PICNN), not a global pixel solve")
        self.model, self.sigma, self.truncate = model, sigma, truncate
        self.tolerance, self.refresh_every, self.full_fraction = tolerance, refresh_every, full_fraction
        self.local_scale = local_scale  # Gc / lc, N/mm^2
        self.r_net = int(model.receptive_radius)
        self.r_s = _smoothing_radius(sigma, truncate)
        self.reference = None   # network input when each pixel was last marked changed
        self.raw = None         # stored network output
        self.smoothed = None    # stored smoothed output
        self.steps_since_full = 0
        self.t_network = 0.0
        self.evaluated_fraction = 0.0

    def local_phase_field(self, capped: np.ndarray) -> np.ndarray:
        """phi_loc = 2 H_c / (Gc/lc + 2 H_c): what the change of a pixel is measured in."""
        return 2.0 * capped / (self.local_scale + 2.0 * capped)

    def _full(self, capped: np.ndarray, local: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        self.raw = self.model.predict(capped)
        self.t_network = time.perf_counter() - started
        self.smoothed = _smooth(self.raw, self.sigma, self.truncate)
        self.reference = local
        self.steps_since_full = 0
        self.evaluated_fraction = 1.0
        return self.smoothed

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        local = self.local_phase_field(capped)
        if self.raw is None or self.raw.shape != capped.shape or self.steps_since_full + 1 >= self.refresh_every:
            return self._full(capped, local)
        self.steps_since_full += 1
        changed = np.abs(local - self.reference) > self.tolerance
        self.t_network, self.evaluated_fraction = 0.0, 0.0
        if not changed.any():
            return self.smoothed
        ny, nx = capped.shape
        reach = self.r_net + self.r_s
        rows, cols = np.nonzero(changed)
        region = _grow((slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1)), reach, ny, nx)
        # square (Chebyshev) dilation = the square receptive field of the convolutions; done on
        # the region around the changed pixels only (it holds the whole dilated set)
        zone = scipy.ndimage.maximum_filter(changed[region], size=2 * reach + 1, mode="constant", cval=False)
        boxes = [_shift(box, region) for box in scipy.ndimage.find_objects(scipy.ndimage.label(zone, structure=np.ones((3, 3), int))[0])]
        area = sum((b[0].stop - b[0].start + 2 * (self.r_s + self.r_net)) * (b[1].stop - b[1].start + 2 * (self.r_s + self.r_net))
                   for b in boxes)
        if area > self.full_fraction * ny * nx:
            return self._full(capped, local)
        # Every output that depends on a pixel of the box grown by r_s - r_net is recomputed
        # below from current inputs: those pixels all restart their drift from now (this
        # keeps later re-evaluations together in time instead of pixel by pixel)
        for box in boxes:
            fresh = _resize(box, self.r_s - self.r_net, ny, nx)
            self.reference[fresh] = local[fresh]
        self.reference[changed] = local[changed]
        started = time.perf_counter()
        raw_updates, evaluated = [], 0
        for box in boxes:
            # network output needed on the box grown by r_s (the filter's support), from inputs grown by r_net more
            out = _grow(box, self.r_s, ny, nx)
            crop = _grow(out, self.r_net, ny, nx)
            raw = self.model.predict(capped[crop])
            raw_updates.append((out, raw[_inner(out, crop)]))
            evaluated += (crop[0].stop - crop[0].start) * (crop[1].stop - crop[1].start)
        self.t_network = time.perf_counter() - started
        self.evaluated_fraction = evaluated / (ny * nx)
        for out, values in raw_updates:
            self.raw[out] = values
        for box in boxes:
            grown = _grow(box, self.r_s, ny, nx)
            self.smoothed[box] = _smooth(self.raw[grown], self.sigma, self.truncate)[_inner(box, grown)]
        return self.smoothed


def _grow(box: tuple[slice, slice], by: int, ny: int, nx: int) -> tuple[slice, slice]:
    return (slice(max(box[0].start - by, 0), min(box[0].stop + by, ny)),
            slice(max(box[1].start - by, 0), min(box[1].stop + by, nx)))


def _resize(box: tuple[slice, slice], by: int, ny: int, nx: int) -> tuple[slice, slice]:
    """Grow (by > 0) or shrink (by < 0) a box; sides on the image edge stay there."""
    if by >= 0:
        return _grow(box, by, ny, nx)
    out = []
    for side, n in zip(box, (ny, nx), strict=True):
        start = side.start if side.start == 0 else side.start - by
        stop = side.stop if side.stop == n else side.stop + by
        out.append(slice(start, max(stop, start)))
    return tuple(out)


def _shift(box: tuple[slice, slice], region: tuple[slice, slice]) -> tuple[slice, slice]:
    """``box`` given in the coordinates of ``region`` -> image coordinates."""
    return (slice(box[0].start + region[0].start, box[0].stop + region[0].start),
            slice(box[1].start + region[1].start, box[1].stop + region[1].start))


def _inner(box: tuple[slice, slice], within: tuple[slice, slice]) -> tuple[slice, slice]:
    """``box`` in the coordinates of the crop ``within``."""
    return (slice(box[0].start - within[0].start, box[0].stop - within[0].start),
            slice(box[1].start - within[1].start, box[1].stop - within[1].start))
