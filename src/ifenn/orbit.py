"""Exact fast CPU inference of the PICNN: symmetric convolutions as orbit sums + one GEMM.

Every kernel of the PICNN is invariant under the 8 symmetries of the square, so its k x k
weights take only n_free = (r + 1)(r + 2)/2 values (r = k // 2; 6 for 5 x 5), one per
orbit {(di, dj): {|di|, |dj|} = {a, b}}, 0 <= a <= b <= r. A layer

    z_o(p) = sum_i sum_(a,b) w[o, i, (a,b)] S_ab(x_i)(p),   S_ab(x)(p) = sum over the orbit of x(p + d)

is then n_free orbit sums per input channel (additions only; separable: the pairs
x(p + a e_y) + x(p - a e_y) first, then the same along x) followed by a matrix product of
(out) x (n_free in) weights with the (n_free in) x pixels sums. For 24 -> 24 channels that
is 24 * 6 * 24 = 3,456 multiply-adds per pixel instead of 24 * 25 * 24 = 14,400, done by
BLAS. Where a layer has fewer outputs than inputs (the last one) the product comes first
and the sums act on the outputs (pointwise channel mixing commutes with every padding mode).
The result is the same network, weights and padding; it differs from the convolution path
by float round-off only (tests/test_picnn.py).

Images are evaluated on boxes: the inputs of a box grown by the receptive radius, padded
only on the sides that lie on the image edge and otherwise shrunk by each "valid" layer,
so a box costs what it covers and is exact wherever it lies. Whole images go box by box
(tiles of ``tile`` pixels, small enough to stay in cache).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from .pixels import Box, box_within, grow_box


class OrbitEvaluator:
    """Inference of a :class:`ifenn.picnn.PICNN` (same outputs, fewer operations).

    ``predict(history)`` mirrors ``PICNN.predict`` for one (ny, nx) map; ``predict_box``
    evaluates only a box of it.
    """

    def __init__(self, model, tile: int = 192, strip_pixels: int = 8192):
        self.model, self.tile, self.strip_pixels = model, int(tile), int(strip_pixels)
        self.radius = model.kernel_size // 2
        self.receptive_radius = int(model.receptive_radius)
        self.padding = model.padding
        self.pairs = [(a, b) for a in range(self.radius + 1) for b in range(a, self.radius + 1)]
        self.layers = []
        with torch.no_grad():
            for layer in model.layers:
                w = layer.free_weight.detach().clone()          # (out, in, n_free)
                n_out, n_in, n_free = w.shape
                if n_out >= n_in:   # orbit sums of the inputs, then (out) x (n_free in)
                    self.layers.append(("inputs", w.permute(0, 2, 1).reshape(n_out, n_free * n_in).contiguous(), n_out))
                else:               # (n_free out) x (in) first, then orbit sums of the outputs
                    self.layers.append(("outputs", w.permute(2, 0, 1).reshape(n_free * n_out, n_in).contiguous(), n_out))
        self.dtype = model.layers[0].free_weight.dtype

    # ------------------------------------------------------------------ one layer
    def _pad(self, x: torch.Tensor, edges: tuple[bool, bool, bool, bool]) -> torch.Tensor:
        """x (c, ny, nx); edges = (first row, last row, first column, last column) on the image edge."""
        r = self.radius
        amounts = (r * edges[2], r * edges[3], r * edges[0], r * edges[1])
        if not any(amounts):
            return x
        if self.padding == "zeros":
            return F.pad(x, amounts)
        return F.pad(x[None], amounts, mode=self.padding)[0]

    def _orbit_sums(self, p: torch.Tensor, out: torch.Tensor, pairs: list[tuple[int, int]]) -> None:
        """p (c, ny + 2r, nx + 2r) -> out (len(pairs), c, ny, nx): S_ab of every channel."""
        r = self.radius
        oy, ox = p.shape[1] - 2 * r, p.shape[2] - 2 * r
        ty = [p[:, r:r + oy, :]] + [p[:, r - a:r - a + oy, :] + p[:, r + a:r + a + oy, :] for a in range(1, r + 1)]

        def pair_x(t: torch.Tensor, b: int, into: torch.Tensor, accumulate: bool) -> None:
            if b == 0:
                into.add_(t[..., r:r + ox]) if accumulate else into.copy_(t[..., r:r + ox])
            elif accumulate:
                into.add_(t[..., r - b:r - b + ox]).add_(t[..., r + b:r + b + ox])
            else:
                torch.add(t[..., r - b:r - b + ox], t[..., r + b:r + b + ox], out=into)

        for k, (a, b) in enumerate(pairs):
            pair_x(ty[a], b, out[k], accumulate=False)
            if a != b:
                pair_x(ty[b], a, out[k], accumulate=True)

    def _layer(self, x: torch.Tensor, kind: str, weight: torch.Tensor, n_out: int, edges) -> torch.Tensor:
        """x (c, ny, nx) -> (n_out, ny', nx'), ny' = ny - 2r on each side not on the edge."""
        r, n_free = self.radius, len(self.pairs)
        if kind == "inputs":
            p = self._pad(x, edges)
            c, oy, ox = p.shape[0], p.shape[1] - 2 * r, p.shape[2] - 2 * r
            # a few rows at a time, so that the sums (n_free c values per pixel) stay in cache
            rows = min(max(2, self.strip_pixels // ox), oy)
            result = torch.empty((n_out, oy, ox), dtype=x.dtype)
            buffer = torch.empty(n_free * c * rows * ox, dtype=x.dtype)
            for start in range(0, oy, rows):
                stop = min(start + rows, oy)
                sums = buffer[: n_free * c * (stop - start) * ox].view(n_free, c, stop - start, ox)
                self._orbit_sums(p[:, start:stop + 2 * r], sums, self.pairs)
                result[:, start:stop] = torch.mm(weight, sums.view(n_free * c, -1)).view(n_out, stop - start, ox)
            return result
        c, ny, nx = x.shape
        mixed = torch.mm(weight, x.reshape(c, ny * nx)).reshape(n_free * n_out, ny, nx)
        p = self._pad(mixed, edges)
        oy, ox = p.shape[1] - 2 * r, p.shape[2] - 2 * r
        p = p.reshape(n_free, n_out, p.shape[1], p.shape[2])
        result = torch.empty((n_free, n_out, oy, ox), dtype=x.dtype)
        for k, pair in enumerate(self.pairs):
            self._orbit_sums(p[k], result[k:k + 1], [pair])
        result = result.sum(0)
        return result

    # ------------------------------------------------------------------ boxes and images
    def _evaluate(self, x: torch.Tensor, edges) -> torch.Tensor:
        """Network input x (ny, nx) of a crop -> phi on the crop shrunk by the receptive radius
        on each side not on the image edge."""
        y = x[None]
        last = len(self.layers) - 1
        for i, (kind, weight, n_out) in enumerate(self.layers):
            y = self._layer(y, kind, weight, n_out, edges)
            if i < last:   # tanh(z) = 2 sigmoid(2 z) - 1: the same function, half the cost of torch.tanh here
                torch.sigmoid_(y.mul_(2.0)).mul_(2.0).sub_(1.0)
            else:
                torch.sigmoid_(y)
        return y[0]

    def predict_box(self, history: np.ndarray, box: Box) -> np.ndarray:
        """phi (float64) on ``box`` of the (ny, nx) history map (N/mm^2), from its inputs
        within the receptive radius only."""
        ny, nx = history.shape
        R = self.receptive_radius
        crop = grow_box(box, R, history.shape)
        edges = (crop[0].start == 0, crop[0].stop == ny, crop[1].start == 0, crop[1].stop == nx)
        with torch.no_grad():
            x = self.model.network_input(torch.as_tensor(np.ascontiguousarray(history[crop]), dtype=self.dtype))
            phi = self._evaluate(x, edges)
        # phi covers the crop less R on every side not on the edge
        covered = (slice(crop[0].start + (0 if edges[0] else R), None), slice(crop[1].start + (0 if edges[2] else R), None))
        return phi.numpy()[box_within(box, covered)].astype(np.float64)

    def predict(self, history: np.ndarray) -> np.ndarray:
        """phi (float64) of a whole (ny, nx) or (n, ny, nx) history map, tile by tile."""
        history = np.asarray(history)
        if history.ndim == 3:
            return np.stack([self.predict(h) for h in history])
        ny, nx = history.shape
        phi = np.empty((ny, nx))
        for y0 in range(0, ny, self.tile):
            for x0 in range(0, nx, self.tile):
                box = (slice(y0, min(y0 + self.tile, ny)), slice(x0, min(x0 + self.tile, nx)))
                phi[box] = self.predict_box(history, box)
        return phi


class ConvolutionEvaluator:
    """The same interface on the network's own convolutions (torch conv2d, as published):
    a box is evaluated on its inputs grown by the receptive radius, padded on every side,
    and the outputs it needs (exact: those at least that radius inside) are kept."""

    def __init__(self, model):
        self.model = model
        self.receptive_radius = int(model.receptive_radius)

    def predict(self, history: np.ndarray) -> np.ndarray:
        return self.model.predict(history)

    def predict_box(self, history: np.ndarray, box: Box) -> np.ndarray:
        crop = grow_box(box, self.receptive_radius, history.shape)
        return self.model.predict(history[crop])[box_within(box, crop)]


EVALUATIONS = {"orbit": OrbitEvaluator, "convolution": ConvolutionEvaluator}


def make_evaluator(model, evaluation: str = "orbit"):
    """``evaluation``: "orbit" (exact reformulation, faster on a CPU) or "convolution"."""
    if evaluation not in EVALUATIONS:
        raise ValueError(f"ifenn.evaluation must be one of {sorted(EVALUATIONS)}, got {evaluation!r}")
    return EVALUATIONS[evaluation](model)
