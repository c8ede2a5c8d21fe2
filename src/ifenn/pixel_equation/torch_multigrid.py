"""The multigrid-preconditioned conjugate gradients of a box of the pixel equation, in torch
(:meth:`ifenn.pixel_equation.torch_backend.TorchPixelEquation.solve_box`).

A port of the compiled ``ifenn_pixel_mg_pcg`` (orbit_kernel.cpp), the same algorithm, not the same
round-off: conjugate gradients in float64 on the cut pixel operator, preconditioned by one V-cycle
in float32: cell-centred levels halved while both sides exceed 4 cells (at most 16,
:func:`ifenn.pixel_equation.definition.level_shapes`), Jacobi smoothing 2 + 2 sweeps (30 on the
coarsest level), bilinear cell-centred transfers (3/4 of the parent, 1/4 of its neighbour; an
edge's replicate ghost keeps the weight, a Dirichlet one drops it), restriction P^T r / 4, coarse
a = the mean of its children, D / 4 per level, and the slits' links redrawn at each level's
spacing (:meth:`ifenn.pixels.SlitCuts.coarse_links`). The certificate is computed in float64 from
the CG's own residual, so it holds whatever precision the preconditioner has.

Deterministic on a GPU: every sum over repeated indices (the restriction P^T, the cut links of a
pixel that loses several) is a gather over a fixed table of contributors summed in a fixed order
(:class:`LinkSum`, :func:`transpose`), never an atomic add, so a rerun on the same GPU gives the
same bits and the same CG iteration counts.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import torch
import torch.nn.functional as F

from ifenn.pixel_equation.definition import level_shapes
from ifenn.pixels import LAPLACIAN_K9_STAR

log = logging.getLogger(__name__)

#: Jacobi sweeps before and after the coarse correction, and on the coarsest level (the compiled V-cycle's)
SMOOTH_SWEEPS, COARSEST_SWEEPS = 2, 30


def ghosted(x: torch.Tensor, replicate: tuple[bool, bool, bool, bool]) -> torch.Tensor:
    """x (n, m) with a one-cell frame: zero (Dirichlet data 0), or the edge's own values on the
    sides (first row, last row, first column, last column) where ``replicate`` (zero flux)."""
    if all(replicate):
        return F.pad(x[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    ext = F.pad(x, (1, 1, 1, 1))
    if replicate[0]:
        ext[0, 1:-1] = x[0]
    if replicate[1]:
        ext[-1, 1:-1] = x[-1]
    if replicate[2]:
        ext[:, 0] = ext[:, 1]
    if replicate[3]:
        ext[:, -1] = ext[:, -2]
    return ext


class LinkSum:
    """Sums of values per repeated index without atomics: ``rows`` (the pixel of each link) ->
    the distinct pixels ``index`` and a (len(index), K) table of their links (padded with a slot
    that reads 0); ``sums(values)`` adds each pixel's links in a fixed order (a gather and a sum)."""

    def __init__(self, rows, device):
        rows = np.asarray(rows, dtype=np.int64)
        order = np.argsort(rows, kind="stable")
        index, starts, counts = np.unique(rows[order], return_index=True, return_counts=True)
        table = np.full((len(index), int(counts.max()) if len(counts) else 0), len(rows), dtype=np.int64)
        for k in range(table.shape[1]):
            has = counts > k
            table[has, k] = order[starts[has] + k]
        self.index = torch.as_tensor(index, device=device)
        self.table = torch.as_tensor(table, device=device)

    def sums(self, values: torch.Tensor) -> torch.Tensor:
        return torch.cat([values, values.new_zeros(1)])[self.table].sum(dim=1)

    def add_to(self, flat: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        """``flat`` with each link's value added at its pixel (``flat`` a fresh 1-D tensor: written in place)."""
        flat[self.index] = flat[self.index] + self.sums(values)
        return flat


class Level:
    """One multigrid level of a box: its shape, ghosts, cut links and (per call) coefficients."""

    def __init__(self, shape, replicate, links, dtype, device):
        self.shape, self.replicate, self.dtype = tuple(shape), tuple(bool(r) for r in replicate), dtype
        self.stencil = torch.as_tensor(LAPLACIAN_K9_STAR, dtype=dtype, device=device).reshape(1, 1, 3, 3)
        rows, cols, weights = links if links is not None else (np.zeros(0, int),) * 2 + (np.zeros(0),)
        self.n_cut = len(rows)
        if self.n_cut:
            self.rows = torch.as_tensor(np.asarray(rows, dtype=np.int64), device=device)
            self.cols = torch.as_tensor(np.maximum(np.asarray(cols, dtype=np.int64), 0), device=device)
            # a link to beyond the box reads the Dirichlet data, 0: its weight is kept off the diagonal only
            self.cut_w = torch.as_tensor(np.asarray(weights, dtype=np.float64), dtype=dtype, device=device)
            self.link_w = torch.as_tensor(np.where(np.asarray(cols) >= 0, weights, 0.0), dtype=dtype, device=device)
            self.links = LinkSum(rows, device)
        self.D = 0.0
        # written in place per solve: a captured CUDA graph reads them where they are
        self.a = torch.zeros(self.shape, dtype=dtype, device=device)
        self.diag, self.inv = torch.zeros_like(self.a), torch.zeros_like(self.a)

    def set_coefficients(self, a: torch.Tensor, D: float) -> None:
        """The level's operator a I - D (K9* - 3 I) with its cut links: diagonal a + 3 D - D sum w."""
        self.D = D
        self.a.copy_(a)
        torch.add(self.a, 3.0 * D, out=self.diag)
        if self.n_cut:
            self.links.add_to(self.diag.view(-1), -D * self.cut_w)
        torch.reciprocal(self.diag, out=self.inv)

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """A x, x with zero Dirichlet data around the box (the padding on the image's edges)."""
        neighbours = F.conv2d(ghosted(x, self.replicate)[None, None], self.stencil)[0, 0]
        out = self.diag * x - self.D * neighbours
        if self.n_cut:  # the cut links' neighbour terms back out: (A_cut x)_i = diag_cut x_i - D (K9* x)_i + D w x_j
            out = self.links.add_to(out.reshape(-1), self.D * self.link_w * x.reshape(-1)[self.cols]).reshape(self.shape)
        return out

    def jacobi(self, b: torch.Tensor, sweeps: int, x: torch.Tensor | None = None) -> torch.Tensor:
        """``sweeps`` Jacobi sweeps x += diag^-1 (b - A x); from x = 0 the first is diag^-1 b."""
        if x is None:
            x, sweeps = self.inv * b, sweeps - 1
        for _ in range(sweeps):
            x = x + self.inv * (b - self.apply(x))
        return x


def transfer(nf: int, nc: int, rep_low: bool, rep_high: bool, device) -> tuple[torch.Tensor, torch.Tensor]:
    """Cell-centred bilinear interpolation in one direction (the compiled ``mg_transfer``): fine i
    takes 3/4 of its parent i // 2 and 1/4 of the parent's neighbour towards i; a neighbour beyond
    the edge is the parent itself (replicate: weight 1) or dropped (weight 0). (nf, 2) indices and
    weights."""
    index, weight = np.zeros((nf, 2), np.int64), np.zeros((nf, 2))
    for i in range(nf):
        p = i // 2
        q = p - 1 if i % 2 == 0 else p + 1
        index[i] = (p, q if 0 <= q < nc else p)
        if 0 <= q < nc:
            weight[i] = (0.75, 0.25)
        elif (q < 0 and rep_low) or (q >= nc and rep_high):
            weight[i] = (1.0, 0.0)
        else:
            weight[i] = (0.75, 0.0)
    return torch.as_tensor(index, device=device), torch.as_tensor(weight, dtype=torch.float32, device=device)


def transpose(transfer: tuple[torch.Tensor, torch.Tensor], n_coarse: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The transpose of a transfer (fine i takes weight[i, s] of coarse index[i, s]) as a gather:
    (n_coarse, K) fine indices each coarse cell receives from and their weights (padding: weight 0),
    so that P^T is a fixed-order sum (no atomics)."""
    index, weight = (t.cpu().numpy() for t in transfer)
    entries = [[] for _ in range(n_coarse)]
    for i in range(len(index)):
        for s in range(2):
            if weight[i, s] != 0.0:
                entries[int(index[i, s])].append((i, weight[i, s]))
    width = max(len(e) for e in entries)
    fine, weights = np.zeros((n_coarse, width), np.int64), np.zeros((n_coarse, width), np.float32)
    for c, e in enumerate(entries):
        for k, (i, w) in enumerate(e):
            fine[c, k], weights[c, k] = i, w
    device = transfer[0].device
    return torch.as_tensor(fine, device=device), torch.as_tensor(weights, device=device)


class DeviceMultigrid:
    """The V-cycle of one box (shape, edges, cut links per level), float32 on ``device``: the
    preconditioner of :meth:`ifenn.pixel_equation.torch_backend.TorchPixelEquation.solve_box` (module doc)."""

    def __init__(self, shape, replicate, level_links, device):
        self.levels = [Level(level_shape, replicate, level_links[k] if k < len(level_links) else None, torch.float32, device)
                       for k, level_shape in enumerate(level_shapes(shape))]
        self.rows, self.cols, self.rows_t, self.cols_t, self.children = [], [], [], [], []
        for fine, coarse in zip(self.levels[:-1], self.levels[1:], strict=True):
            (nf, mf), (nc, mc) = fine.shape, coarse.shape
            self.rows.append(transfer(nf, nc, replicate[0], replicate[1], device))
            self.cols.append(transfer(mf, mc, replicate[2], replicate[3], device))
            self.rows_t.append(transpose(self.rows[-1], nc))
            self.cols_t.append(transpose(self.cols[-1], mc))
            # the (up to 4) children of each coarse cell: an odd edge counts its last row / column twice
            i0 = torch.arange(nc, device=device) * 2
            j0 = torch.arange(mc, device=device) * 2
            self.children.append((i0, torch.clamp(i0 + 1, max=nf - 1), j0, torch.clamp(j0 + 1, max=mf - 1)))

    def set_coefficients(self, a: torch.Tensor, D: float) -> None:
        """Every level's coefficients for the finest ``a``: coarse a the mean of its children, D / 4."""
        for k, level in enumerate(self.levels):
            level.set_coefficients(a, D)
            if k + 1 < len(self.levels):
                i0, i1, j0, j1 = self.children[k]
                top, bottom = level.a[i0], level.a[i1]
                a = 0.25 * (top[:, j0] + top[:, j1] + bottom[:, j0] + bottom[:, j1])
                D = D / 4.0

    def _restrict(self, k: int, r: torch.Tensor) -> torch.Tensor:
        """P^T r / 4, separably (rows, then columns), each as a gather over the transposed transfer."""
        (row_i, row_w), (col_i, col_w) = self.rows_t[k], self.cols_t[k]
        t = (0.25 * row_w[:, :, None] * r[row_i]).sum(dim=1)          # (nc, m): row_i (nc, K)
        return (col_w[None, :, :] * t[:, col_i]).sum(dim=2)          # (nc, mc): col_i (mc, K)

    def _prolong(self, k: int, x: torch.Tensor) -> torch.Tensor:
        """P x, separably."""
        (row_i, row_w), (col_i, col_w) = self.rows[k], self.cols[k]
        t = x[:, col_i[:, 0]] * col_w[:, 0] + x[:, col_i[:, 1]] * col_w[:, 1]
        return t[row_i[:, 0]] * row_w[:, :1] + t[row_i[:, 1]] * row_w[:, 1:]

    def vcycle(self, b: torch.Tensor, k: int = 0) -> torch.Tensor:
        """One symmetric V-cycle from x = 0 on level ``k`` (float32)."""
        level = self.levels[k]
        if k + 1 == len(self.levels):
            return level.jacobi(b, COARSEST_SWEEPS)
        x = level.jacobi(b, SMOOTH_SWEEPS)
        x = x + self._prolong(k, self.vcycle(self._restrict(k, b - level.apply(x)), k + 1))
        return level.jacobi(b, SMOOTH_SWEEPS, x)


class BoxCG:
    """The conjugate gradients of one box (float64), on buffers kept between solves, so that on a
    GPU an iteration is one captured CUDA graph (the launches of a V-cycle on a 600 x 600 image, a
    thousand small kernels, cost more than their arithmetic); on the CPU the same iteration runs
    eagerly. An iteration: q = A p, the step, the certificate max |r| / a; then, only while it
    fails (always, inside a graph: the last V-cycle is then spare), the next V-cycle and direction."""

    def __init__(self, level: Level, grid: DeviceMultigrid):
        self.level, self.grid = level, grid
        zeros = functools.partial(torch.zeros, level.shape, dtype=torch.float64, device=level.a.device)
        self.r, self.z, self.p, self.delta, self.inv_a = zeros(), zeros(), zeros(), zeros(), zeros()
        self.rz = torch.zeros((), dtype=torch.float64, device=level.a.device)
        self.worst = torch.zeros((), dtype=torch.float64, device=level.a.device)
        self.graph = None
        # fused: every iteration also prepares the next direction, as the graph does (on the CPU
        # only to test the captured iteration's arithmetic)
        self.use_graph = self.fused = level.a.device.type == "cuda"

    def start(self) -> float:
        """delta = 0 and the certificate of the box's residual (``r``, set by the caller)."""
        self.delta.zero_()
        torch.amax(self.r.abs() * self.inv_a, out=self.worst)
        return float(self.worst)

    def _precondition(self) -> None:
        self.z.copy_(self.grid.vcycle(self.r.to(torch.float32)))

    def first_direction(self) -> None:
        self._precondition()
        self.p.copy_(self.z)
        self.rz.copy_(torch.sum(self.r * self.z))

    def _update(self) -> None:
        q = self.level.apply(self.p)
        alpha = self.rz / torch.sum(self.p * q)
        self.delta.add_(alpha * self.p)
        self.r.sub_(alpha * q)
        torch.amax(self.r.abs() * self.inv_a, out=self.worst)

    def _next_direction(self) -> None:
        self._precondition()
        rz_new = torch.sum(self.r * self.z)
        self.p.mul_(rz_new / self.rz).add_(self.z)
        self.rz.copy_(rz_new)

    def _iteration(self) -> None:
        self._update()
        self._next_direction()

    def iterate(self, target: float) -> float:
        """One iteration; returns its certificate (the one sync of an iteration)."""
        if self.use_graph and self.graph is None:
            self._capture()
        if self.graph is not None:
            self.graph.replay()
            return float(self.worst)
        if self.fused:
            self._iteration()
            return float(self.worst)
        self._update()
        worst = float(self.worst)
        if worst > target:
            self._next_direction()
        return worst

    def _capture(self) -> None:
        """Record an iteration as a CUDA graph (after warm-up runs on a side stream, which move the
        state: it is put back). Where capture fails, the iterations run eagerly, and the log says so."""
        state = [t.clone() for t in (self.r, self.z, self.p, self.delta, self.rz, self.worst)]
        try:
            stream = torch.cuda.Stream()
            stream.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(stream):
                for _ in range(2):
                    self._iteration()
            torch.cuda.current_stream().wait_stream(stream)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                self._iteration()
            self.graph = graph
        except Exception as error:   # noqa: BLE001 (whatever the capture raised; pragma: a GPU's)
            log.warning("CUDA graph capture of the correction failed (%s): its iterations run eagerly", error)
            self.use_graph = False
        for buffer, saved in zip((self.r, self.z, self.p, self.delta, self.rz, self.worst), state, strict=True):
            buffer.copy_(saved)
