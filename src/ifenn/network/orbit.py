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

Where a C++ compiler is at hand (``kernel="auto"``, the default) the layers run instead in a
compiled kernel (:mod:`ifenn.network.orbit_kernel`) that fuses the sums and the product on chunks of
32 pixels of a row, about 2.5 x faster than the torch path on one core, and evaluates any
set of rows and runs of pixels: :class:`NetworkState` keeps every layer's activations on the
whole image, so that a change of some inputs is carried through the layers only where it
reaches (process-zone inference, :mod:`ifenn.hybrid.process_zone`).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import torch
import torch.nn.functional as F

from ifenn.pixels import Box, box_within, grow_box

from . import orbit_kernel

KERNELS = ("auto", "compiled", "torch")


class OrbitEvaluator:
    """Inference of a :class:`ifenn.network.picnn.PICNN` (same outputs, fewer operations).

    ``predict(history)`` mirrors ``PICNN.predict`` for one (ny, nx) map; ``predict_box``
    evaluates only a box of it; ``network_state(shape)`` keeps the layers' activations of a
    whole image for incremental updates. ``kernel``: "auto" (the compiled kernel where it
    builds, else torch), "compiled" (an error where it does not) or "torch".
    """

    def __init__(self, model, tile: int = 192, strip_pixels: int = 8192, kernel: str = "auto"):
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
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
        self.library = None
        if kernel != "torch":
            self.library = orbit_kernel.load() if orbit_kernel.supports(model.kernel_size) else None
            if self.library is None and kernel == "compiled":
                raise RuntimeError(f"the compiled orbit kernel is not available for kernel size {model.kernel_size} here")
        self.kernel = "compiled" if self.library is not None else "torch"   # what runs the layers
        with torch.no_grad():   # (out, n_free in) weights of every layer, float32, for the kernel
            self.kernel_weights = [np.ascontiguousarray(layer.free_weight.detach().permute(0, 2, 1).reshape(layer.out_ch, -1)
                                                        .numpy(), dtype=np.float32) for layer in model.layers]
        self._scratch = None

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
        for i, (kind, weight, n_out) in enumerate(self.layers):
            y = self._activate(i, self._layer(y, kind, weight, n_out, edges))
        return y[0]

    def _activate(self, i: int, y: torch.Tensor) -> torch.Tensor:
        if i < len(self.layers) - 1:   # tanh(z) = 2 sigmoid(2 z) - 1: the same function, half the cost of torch.tanh here
            return torch.sigmoid_(y.mul_(2.0)).mul_(2.0).sub_(1.0)
        return torch.sigmoid_(y)

    def apply_layer(self, i: int, x: np.ndarray, y: np.ndarray, mask: np.ndarray, origin: tuple[int, int]) -> None:
        """Layer i from the padded activations x (c_in, ny + 2r, nx + 2r) into y (c_out, same):
        y is recomputed at the pixels of ``mask`` (bool, image pixels from ``origin`` = (row,
        column) on), or, on the torch path, on their bounding box; padding is not touched.
        x and y are layer buffers of a :class:`NetworkState` (float32, contiguous, with the slack
        the compiled kernel reads past a row's end)."""
        r, (y0, x0) = self.radius, origin
        if self.library is not None:
            if not all(a.dtype == np.float32 and a.flags.c_contiguous for a in (x, y)) or x.shape[1:] != y.shape[1:]:
                raise ValueError("apply_layer needs two float32 layer buffers of one NetworkState")
            mask = np.ascontiguousarray(mask, dtype=bool)
            ny, nx = x.shape[1] - 2 * r, x.shape[2] - 2 * r
            code = self.library.ifenn_orbit_layer(x.ctypes.data, x.shape[0], ny, nx, r, y.ctypes.data, y.shape[0],
                                                  self.kernel_weights[i].ctypes.data, mask.ctypes.data, mask.shape[0],
                                                  mask.shape[1], y0, x0,
                                                  orbit_kernel.ACTIVATIONS["tanh" if i < len(self.layers) - 1 else "sigmoid"])
            if code != 0:
                raise RuntimeError(f"the compiled kernel has no instance for kernel radius {r}")
            return
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if rows.size == 0:
            return
        (a, b), (c, d) = (y0 + rows[0], y0 + rows[-1] + 1), (x0 + cols[0], x0 + cols[-1] + 1)
        kind, weight, n_out = self.layers[i]
        with torch.no_grad():
            crop = torch.as_tensor(x[:, a:b + 2 * r, c:d + 2 * r], dtype=self.dtype)
            y[:, a + r:b + r, c + r:d + r] = self._activate(i, self._layer(crop, kind, weight, n_out, (False,) * 4)).numpy()

    def dilate(self, mask: np.ndarray, r: int) -> np.ndarray:
        """``mask`` (bool) grown by r pixels in a square window (none outside it)."""
        if self.library is None:
            return scipy.ndimage.maximum_filter(mask, size=2 * r + 1, mode="constant", cval=False)
        mask = np.ascontiguousarray(mask, dtype=bool)
        out, scratch = np.empty_like(mask), np.empty_like(mask)
        self.library.ifenn_dilate(mask.ctypes.data, out.ctypes.data, scratch.ctypes.data, mask.shape[0], mask.shape[1], r)
        return out

    def network_state(self, shape: tuple[int, int]) -> NetworkState:
        return NetworkState(self, shape)

    def prepare(self, shape: tuple[int, int]) -> None:
        """Allocate what ``predict`` of a ``shape`` image uses, ahead of the first call (as the
        FEM step builds its matrix ahead of the first solve)."""
        if self.library is not None and (self._scratch is None or self._scratch.shape != tuple(shape)):
            self._scratch = NetworkState(self, shape)

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
        if self.library is not None:
            self.prepare(history.shape)
            return self._scratch.full(history).astype(np.float64)
        ny, nx = history.shape
        phi = np.empty((ny, nx))
        for y0 in range(0, ny, self.tile):
            for x0 in range(0, nx, self.tile):
                box = (slice(y0, min(y0 + self.tile, ny)), slice(x0, min(x0 + self.tile, nx)))
                phi[box] = self.predict_box(history, box)
        return phi


def _padding_index(n: int, r: int, mode: str) -> np.ndarray:
    """For the r pixels before and after an axis of n: the index of the pixel each repeats."""
    outside = np.concatenate([np.arange(-r, 0), np.arange(n, n + r)])
    if mode == "replicate":
        return np.clip(outside, 0, n - 1)
    if mode == "reflect":
        return np.where(outside < 0, -outside, 2 * (n - 1) - outside)
    return outside % n   # circular


class NetworkState:
    """The activations of every layer of the network on a whole (ny, nx) image, padded by the
    kernel radius r as the convolutions pad them, kept between calls.

    ``full(history)`` evaluates every layer everywhere. ``propagate(mask, origin)`` takes a
    set of pixels whose input was rewritten (``set_inputs``) and recomputes layer 1 within r
    of them, layer 2 within r of those, and so on: exactly the activations that depend on
    the rewritten inputs. The others keep the values they were last computed with.
    """

    def __init__(self, evaluator: OrbitEvaluator, shape: tuple[int, int]):
        self.evaluator, self.shape = evaluator, tuple(shape)
        ny, nx = self.shape
        self.r = r = evaluator.radius
        self.layers = []   # padded float32 images, one per layer boundary (input first)
        for channels in evaluator.model.channels:
            size = channels * (ny + 2 * r) * (nx + 2 * r)
            # np.full writes every page now (np.zeros would defer that to the first evaluation)
            self.layers.append(np.full(size + orbit_kernel.SLACK, 0.0, dtype=np.float32)[:size].reshape(channels, ny + 2 * r, nx + 2 * r))
        padding = evaluator.padding
        self._padding = None if padding == "zeros" else (_padding_index(ny, r, padding) + r, _padding_index(nx, r, padding) + r)
        # the padded rows (columns) before and after the image, and the halves of each
        self._outside = (np.r_[np.arange(r), np.arange(ny + r, ny + 2 * r)], np.r_[np.arange(r), np.arange(nx + r, nx + 2 * r)])
        self._sides = {(True, False): np.arange(r), (False, True): np.arange(r, 2 * r), (True, True): np.arange(2 * r)}

    @property
    def output(self) -> np.ndarray:
        """The network output phi (ny, nx), float32 (a view)."""
        r, (ny, nx) = self.r, self.shape
        return self.layers[-1][0, r:r + ny, r:r + nx]

    def _fill_padding(self, i: int, box: Box | None = None) -> None:
        """Rewrite the padding of layer boundary i that repeats the pixels of ``box`` (image
        coordinates; None: the whole image)."""
        if self._padding is None:
            return
        r, (ny, nx), x = self.r, self.shape, self.layers[i]
        (a, b), (c, d) = ((0, ny), (0, nx)) if box is None else ((box[0].start, box[0].stop), (box[1].start, box[1].stop))
        rows, cols = self._padding
        top, bottom, left, right = a <= r, b >= ny - r, c <= r, d >= nx - r
        if top or bottom:
            pick = self._sides[top, bottom]
            x[:, self._outside[0][pick], r + c:r + d] = x[:, rows[pick], r + c:r + d]
        if left or right:
            pick = self._sides[left, right]
            span = slice(0 if top else a + r, ny + 2 * r if bottom else b + r)
            x[:, span, self._outside[1][pick]] = x[:, span, cols[pick]]

    def full(self, history: np.ndarray) -> np.ndarray:
        """Evaluate the whole image; returns ``output``."""
        r, (ny, nx) = self.r, self.shape
        with torch.no_grad():
            self.layers[0][0, r:r + ny, r:r + nx] = self.evaluator.model.network_input(torch.as_tensor(history, dtype=torch.float32)).numpy()
        self._fill_padding(0)
        everywhere = np.ones(self.shape, dtype=bool)
        for i in range(len(self.layers) - 1):
            self.evaluator.apply_layer(i, self.layers[i], self.layers[i + 1], everywhere, (0, 0))
            self._fill_padding(i + 1)
        return self.output

    def set_inputs(self, history: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
        """Rewrite the network input at pixels (rows, cols) from the history image."""
        r = self.r
        with torch.no_grad():
            values = self.evaluator.model.network_input(torch.as_tensor(history[rows, cols], dtype=torch.float32)).numpy()
        self.layers[0][0, rows + r, cols + r] = values
        if rows.size:
            self._fill_padding(0, (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1)))

    def propagate(self, mask: np.ndarray, origin: tuple[int, int]) -> np.ndarray:
        """Recompute what depends on the rewritten inputs ``mask`` (bool, a crop of the image
        from ``origin``, large enough to hold them grown by the receptive radius). Returns the
        output pixels recomputed (bool, the same crop)."""
        for i in range(len(self.layers) - 1):
            mask = self.evaluator.dilate(mask, self.r)
            self.evaluator.apply_layer(i, self.layers[i], self.layers[i + 1], mask, origin)
            self._fill_padding(i + 1, (slice(origin[0], origin[0] + mask.shape[0]), slice(origin[1], origin[1] + mask.shape[1])))
        return mask


class ConvolutionEvaluator:
    """The same interface on the network's own convolutions (torch conv2d, as published):
    a box is evaluated on its inputs grown by the receptive radius, padded on every side,
    and the outputs it needs (exact: those at least that radius inside) are kept."""

    kernel = "conv2d"

    def __init__(self, model):
        self.model = model
        self.receptive_radius = int(model.receptive_radius)

    def predict(self, history: np.ndarray) -> np.ndarray:
        return self.model.predict(history)

    def prepare(self, shape: tuple[int, int]) -> None:
        """Nothing to allocate ahead: conv2d allocates per call."""

    def predict_box(self, history: np.ndarray, box: Box) -> np.ndarray:
        crop = grow_box(box, self.receptive_radius, history.shape)
        return self.model.predict(history[crop])[box_within(box, crop)]


EVALUATIONS = {"orbit": OrbitEvaluator, "convolution": ConvolutionEvaluator}


def make_evaluator(model, evaluation: str = "orbit"):
    """``evaluation``: "orbit" (exact reformulation, faster on a CPU) or "convolution"."""
    if evaluation not in EVALUATIONS:
        raise ValueError(f"ifenn.evaluation must be one of {sorted(EVALUATIONS)}, got {evaluation!r}")
    return EVALUATIONS[evaluation](model)
