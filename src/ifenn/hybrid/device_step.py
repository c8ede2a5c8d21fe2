"""The verified phase-field step in torch, on the run's device (the GPU's path).

The same step as :class:`ifenn.hybrid.verification.VerifiedInference` (read its module doc for
the equation, the certificate and the warm starts), with every array a torch tensor on one
device: the history goes up once per call, the network (its own convolutions), the Gaussian
smoothing, the residual check and the multigrid-preconditioned correction run there, and the
certified phi comes down once. On the CPU the workflow keeps the compiled step (``device: cpu``
gives today's phi bit for bit); this one is what a CUDA device runs, and the tests run it on the
CPU too, where torch is its own reference.

The correction is a port of the compiled ``ifenn_pixel_mg_pcg`` (orbit_kernel.cpp), the same
algorithm, not the same round-off: conjugate gradients in float64 on the cut pixel operator,
preconditioned by one V-cycle in float32: cell-centred levels halved while both sides exceed 4
cells (at most 16), Jacobi smoothing 2 + 2 sweeps (30 on the coarsest level), bilinear
cell-centred transfers (3/4 of the parent, 1/4 of its neighbour; an edge's replicate ghost keeps
the weight, a Dirichlet one drops it), restriction P^T r / 4, coarse a = the mean of its
children, D / 4 per level, and the slits' links redrawn at each level's spacing
(:meth:`ifenn.pixels.SlitCuts.coarse_links`). The certificate is computed in float64 from the
CG's own residual, so it holds whatever precision the preconditioner has.

What differs from the CPU step, by design for a device where a launch costs more than a pixel:
the residual is recomputed on the whole image (no stale-pixel bookkeeping), the network is
evaluated on the whole image each call (no process zone), and the failing pixels are corrected
in one box per round (their bounding box grown by the margin; the whole image past
``GLOBAL_FRACTION``). The certificate is the same: max |r| <= tolerance over the whole image, or
the step is reported (``residual_after``).

Deterministic on a GPU: every sum over repeated indices (the restriction P^T, the cut links of a
pixel that loses several) is a gather over a fixed table of contributors summed in a fixed order
(:class:`_LinkSum`, :func:`_transpose`), never an atomic add, so a rerun on the same GPU gives the
same bits and the same CG iteration counts. A step's scalars (the certificates, the failing share,
the box of the failing pixels) come to the host together, one transfer each time the loop needs
them; the smoothing's kernel and index go up once per image size.
"""

from __future__ import annotations

import functools
import logging
import time

import numpy as np
import torch
import torch.nn.functional as F

from ifenn.errors import SolverDivergedError
from ifenn.hybrid.verification import _DEFAULTS, WARM_STARTS
from ifenn.pixels import LAPLACIAN_K9_STAR, Box, SlitCuts, box_area, grow_box

log = logging.getLogger(__name__)

#: Jacobi sweeps before and after the coarse correction, and on the coarsest level (the compiled V-cycle's)
SMOOTH_SWEEPS, COARSEST_SWEEPS = 2, 30


def _ghosted(x: torch.Tensor, replicate: tuple[bool, bool, bool, bool]) -> torch.Tensor:
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


class _LinkSum:
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


class _Level:
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
            self.links = _LinkSum(rows, device)
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
        neighbours = F.conv2d(_ghosted(x, self.replicate)[None, None], self.stencil)[0, 0]
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


def _transfer(nf: int, nc: int, rep_low: bool, rep_high: bool, device) -> tuple[torch.Tensor, torch.Tensor]:
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


def _transpose(transfer: tuple[torch.Tensor, torch.Tensor], n_coarse: int) -> tuple[torch.Tensor, torch.Tensor]:
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
    preconditioner of :meth:`DevicePixelEquation.solve_box` (module doc)."""

    def __init__(self, shape, replicate, level_links, device):
        self.levels = [_Level(shape, replicate, level_links[0], torch.float32, device)]
        while self.levels[-1].shape[0] > 4 and self.levels[-1].shape[1] > 4 and len(self.levels) < 16:
            n, m = self.levels[-1].shape
            coarse = ((n + 1) // 2, (m + 1) // 2)
            k = len(self.levels)
            self.levels.append(_Level(coarse, replicate, level_links[k] if k < len(level_links) else None, torch.float32, device))
        self.rows, self.cols, self.rows_t, self.cols_t, self.children = [], [], [], [], []
        for fine, coarse in zip(self.levels[:-1], self.levels[1:], strict=True):
            (nf, mf), (nc, mc) = fine.shape, coarse.shape
            self.rows.append(_transfer(nf, nc, replicate[0], replicate[1], device))
            self.cols.append(_transfer(mf, mc, replicate[2], replicate[3], device))
            self.rows_t.append(_transpose(self.rows[-1], nc))
            self.cols_t.append(_transpose(self.cols[-1], mc))
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


class _BoxCG:
    """The conjugate gradients of one box (float64), on buffers kept between solves, so that on a
    GPU an iteration is one captured CUDA graph (the launches of a V-cycle on a 600 x 600 image, a
    thousand small kernels, cost more than their arithmetic); on the CPU the same iteration runs
    eagerly. An iteration: q = A p, the step, the certificate max |r| / a; then, only while it
    fails (always, inside a graph: the last V-cycle is then spare), the next V-cycle and direction."""

    def __init__(self, level: _Level, grid: DeviceMultigrid):
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


class DevicePixelEquation:
    """The pixel equation of one image in torch on ``device`` (float64): the whole image's
    residual and box solves (:class:`ifenn.hybrid.verification.PixelEquation`'s, same operator,
    same cut links)."""

    def __init__(self, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts: SlitCuts | None = None,
                 device="cpu"):
        if padding not in ("replicate", "zeros"):
            raise ValueError(f"pixel equation padding must be 'replicate' or 'zeros', got {padding!r}")
        self.Gc, self.lc, self.h_px, self.padding = Gc, lc, h_px, padding
        self.cuts = cuts if cuts else None
        self.device = torch.device(device)
        self.diffusion, self.reaction0 = Gc * lc / h_px**2, Gc / lc
        self._stencil = torch.as_tensor(LAPLACIAN_K9_STAR, dtype=torch.float64, device=self.device).reshape(1, 1, 3, 3)
        self._cuts_t = None
        if self.cuts is not None:
            self._cuts_t = (torch.as_tensor(self.cuts.rows, device=self.device), torch.as_tensor(self.cuts.cols, device=self.device),
                            torch.as_tensor(self.cuts.weights, dtype=torch.float64, device=self.device),
                            _LinkSum(self.cuts.rows, self.device))
        self._grids: dict = {}   # box -> its CG (finest level in float64, multigrid, buffers, graph)

    def residual(self, phi: torch.Tensor, history: torch.Tensor, normalised: bool = True) -> torch.Tensor:
        """R = a phi - D (K9*(phi) - 3 phi) - 2 H on the whole image (the slits' links cut), or R / a."""
        rep = self.padding == "replicate"
        neighbours = F.conv2d(_ghosted(phi, (rep,) * 4)[None, None], self._stencil)[0, 0]
        a = self.reaction0 + 2.0 * history
        residual = a * phi - self.diffusion * (neighbours - 3.0 * phi) - 2.0 * history
        if self._cuts_t is not None:
            rows, cols, weights, links = self._cuts_t
            flat = phi.reshape(-1)
            flux = links.add_to(torch.zeros_like(flat), weights * (flat[cols] - flat[rows]))
            residual = residual + self.diffusion * flux.reshape(phi.shape)
        return residual / a if normalised else residual

    def _grid(self, box: Box, image_shape) -> _BoxCG:
        key = (box[0].start, box[0].stop, box[1].start, box[1].stop)
        if key not in self._grids:
            ny, nx = image_shape
            edges = (box[0].start == 0, box[0].stop == ny, box[1].start == 0, box[1].stop == nx)
            replicate = edges if self.padding == "replicate" else (False,) * 4
            shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
            links = [None]
            if self.cuts is not None:
                links = [self.cuts.in_box(box)]
                coarse = shape
                while coarse[0] > 4 and coarse[1] > 4 and len(links) < 16:
                    coarse = ((coarse[0] + 1) // 2, (coarse[1] + 1) // 2)
                    links.append(self.cuts.coarse_links(box, len(links), coarse))
            if len(self._grids) > 16:
                self._grids.clear()
            self._grids[key] = _BoxCG(_Level(shape, replicate, links[0], torch.float64, self.device),
                                      DeviceMultigrid(shape, replicate, links, self.device))
        return self._grids[key]

    def solve_box(self, phi: torch.Tensor, history: torch.Tensor, box: Box, target: float, maxiter: int = 1000) -> tuple[float, int]:
        """Solve the pixel equation on ``box`` in place in ``phi`` (the values around it fixed) to
        max |r| <= ``target`` inside it: CG in float64 preconditioned with one float32 V-cycle.
        Returns (max |r| reached, iterations); raises if ``maxiter`` iterations do not get there."""
        cg = self._grid(box, phi.shape)
        a = self.reaction0 + 2.0 * history[box]
        cg.level.set_coefficients(a, self.diffusion)
        cg.grid.set_coefficients(a, self.diffusion)
        torch.reciprocal(a, out=cg.inv_a)
        cg.r.copy_(-self.residual(phi, history, normalised=False)[box])   # the correction solves A delta = -R(phi)
        worst, iterations = cg.start(), 0
        if worst > target:
            cg.first_direction()
            while worst > target:
                if iterations == maxiter:
                    raise SolverDivergedError(f"pixel correction on {box} did not reach max |r| = {target:g} in {maxiter} iterations "
                                       f"(reached {worst:g})")
                iterations += 1
                worst = cg.iterate(target)
        phi[box] += cg.delta
        return worst, iterations


def gaussian_smoothing(image: torch.Tensor, sigma: float | None, truncate: float = 4.0) -> torch.Tensor:
    """scipy.ndimage.gaussian_filter(image, sigma, truncate=truncate, mode='reflect') in torch
    (the same kernel, radius int(truncate sigma + 0.5); 'reflect' = the edge value repeated,
    d c b a | a b c d), separably."""
    if not sigma:
        return image

    def along_last(t: torch.Tensor) -> torch.Tensor:
        kernel, index = _smoothing_tables(float(sigma), float(truncate), t.shape[-1], t.dtype, t.device)
        return F.conv1d(t[:, index][:, None], kernel)[:, 0]

    return along_last(along_last(image).T).T


@functools.lru_cache(maxsize=32)
def _smoothing_tables(sigma: float, truncate: float, n: int, dtype, device) -> tuple[torch.Tensor, torch.Tensor]:
    """The smoothing's kernel (1, 1, 2 radius + 1) and its reflecting index for a line of ``n``
    pixels, on ``device``: made and uploaded once per size, not per call."""
    radius = int(truncate * sigma + 0.5)
    x = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * x**2 / sigma**2)
    index = np.arange(-radius, n + radius)
    period = np.mod(index, 2 * n)
    index = np.where(period < n, period, 2 * n - 1 - period)   # half-sample symmetric
    return (torch.as_tensor(kernel / kernel.sum(), dtype=dtype, device=device).reshape(1, 1, -1),
            torch.as_tensor(index, device=device))


def _bounding_box(mask: torch.Tensor, grow: int) -> Box | None:
    """The box of the True pixels grown by ``grow`` (None if there are none): found on the device
    and brought to the host in one transfer (nonzero and five reads would sync six times)."""
    rows, cols = mask.any(dim=1), mask.any(dim=0)

    def first_last(v):
        return torch.argmax(v.to(torch.uint8)), v.numel() - 1 - torch.argmax(torch.flip(v, (0,)).to(torch.uint8))

    found, r0, r1, c0, c1 = torch.stack([rows.any().long(), *first_last(rows), *first_last(cols)]).tolist()
    if not found:
        return None
    return grow_box((slice(r0, r1 + 1), slice(c0, c1 + 1)), grow, tuple(mask.shape))


class DeviceVerifiedInference:
    """:class:`ifenn.hybrid.verification.VerifiedInference` on a torch device (module doc): called
    with a history image (numpy, N/mm^2), returns the certified phi (numpy), with the same
    records (``corrected_fraction``, ``residual_before`` / ``residual_after``, ``solve_work``,
    ``t_check``, ``t_correction``, ``t_network``, ``evaluated_fraction``). ``model``: the PICNN
    (on ``device``), or None with ``warm_start='previous'``. ``input_scale``: the network is fed
    that times the (capped) H: a network trained on another material at the same lc / h_px
    (:func:`ifenn.hybrid.runs.network_service`; ``history_cap`` is then the published cap over it)."""

    #: correction boxes over more than this share of the image: the whole image instead (as the
    #: CPU step); on a GPU every correction is on the whole image (``global_fraction`` 0: one
    #: shape, so one captured graph, and a pixel costs less than a launch there)
    GLOBAL_FRACTION = 0.5

    def __init__(self, model, equation: DevicePixelEquation, tolerance: float = _DEFAULTS["tolerance"],
                 margin_lc: float = _DEFAULTS["margin_lc"], max_rounds: int = _DEFAULTS["max_rounds"],
                 solve_fraction: float = _DEFAULTS["solve_fraction"], warm_start: str = _DEFAULTS["warm_start"],
                 history_cap: float | None = None, cap_history: bool = _DEFAULTS["cap_history"],
                 sigma: float | None = None, truncate: float = 4.0, network_tolerance: float | None = None,
                 input_scale: float = 1.0):
        if warm_start not in WARM_STARTS:
            raise ValueError(f"verification warm_start must be one of {WARM_STARTS}, got {warm_start!r}")
        if warm_start != "previous" and model is None:
            raise ValueError("verification warm_start 'network' needs a network")
        if not tolerance > 0:
            raise ValueError(f"verification tolerance must be > 0, got {tolerance}")
        self.model, self.equation, self.tolerance = model, equation, float(tolerance)
        self.input_scale = float(input_scale)
        self.device = equation.device
        self.margin = int(np.ceil(float(margin_lc) * equation.lc / equation.h_px))
        self.max_rounds, self.solve_fraction, self.warm_start = int(max_rounds), float(solve_fraction), warm_start
        self.history_cap = None if history_cap is None else float(history_cap)
        self.cap_history = bool(cap_history)
        self.sigma, self.truncate = sigma, truncate
        # the network's answer is taken only where its input's local phi moved by network_tolerance since
        # it was last taken there, and within the network's reach and the smoothing's radius of such pixels
        self.network_tolerance = network_tolerance
        # (the CPU's process zone rewrites the inputs within the reach of such pixels: the outputs within twice it change)
        reach = sum(layer.kernel_size // 2 for layer in getattr(model, "layers", ()))
        self.zone_radius = 2 * reach + (int(truncate * float(sigma) + 0.5) if sigma else 0)
        self.reference = None   # per pixel, the local phi of the input when the network's answer was last taken
        self.kernel = "" if model is None else "conv2d"
        self.global_fraction = 0.0 if self.device.type == "cuda" else self.GLOBAL_FRACTION
        self.phi = self.prediction = None   # last verified phi, last network prediction (tensors on the device)
        self.t_network = self.t_check = self.t_correction = 0.0
        self.evaluated_fraction = self.corrected_fraction = self.failing_fraction = 0.0
        self.residual_before = self.residual_after = 0.0
        self.solve_iterations, self.solve_work = 0, 0.0

    def start_from(self, phi: np.ndarray) -> None:
        if self.phi is None:
            self.phi = torch.as_tensor(np.asarray(phi, dtype=np.float64), device=self.device).clone()

    @torch.no_grad()
    def _network(self, capped: torch.Tensor) -> torch.Tensor:
        started = time.perf_counter()
        dtype = next(self.model.parameters()).dtype
        raw = self.model.phase_field((capped * self.input_scale).to(dtype)[None, None])[0, 0].to(torch.float64)
        out = gaussian_smoothing(raw, self.sigma, self.truncate)
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        self.t_network, self.evaluated_fraction = time.perf_counter() - started, 1.0
        return out

    def _candidate(self, capped: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        if self.warm_start == "previous":
            self.t_network, self.evaluated_fraction = 0.0, 0.0
            if self.phi is None:   # the local solution 2H / (Gc/lc + 2H)
                return 2.0 * history / (self.equation.reaction0 + 2.0 * history)
            return self.phi.clone()
        prediction = self._network(capped)
        local = 2.0 * capped / (self.equation.reaction0 + 2.0 * capped)
        if self.prediction is None or self.phi is None:
            self.prediction, self.reference = prediction, local
            return prediction.clone()
        if self.network_tolerance is not None:   # the CPU's process zone, as a mask on the whole image's answer
            moved = (local - self.reference).abs() > self.network_tolerance
            self.reference = torch.where(moved, local, self.reference)
            radius = self.zone_radius
            zone = F.max_pool2d(moved[None, None].to(torch.float32), 2 * radius + 1, stride=1, padding=radius)[0, 0] > 0
            prediction = torch.where(zone, prediction, self.prediction)
            self.evaluated_fraction = float(zone.float().mean())
        if self.warm_start == "network":
            candidate = torch.where(prediction != self.prediction, prediction, self.phi)
        else:   # "increment": the network's change added to the last verified phi
            candidate = self.phi + (prediction - self.prediction)
        self.prediction = prediction
        return candidate

    @torch.no_grad()
    def __call__(self, history: np.ndarray) -> np.ndarray:
        history = torch.as_tensor(np.asarray(history, dtype=np.float64), device=self.device)   # up once
        network_input = history if self.history_cap is None else torch.clamp(history, max=self.history_cap)
        if self.cap_history:
            history = network_input
        phi = self._candidate(network_input, history)
        started = time.perf_counter()
        equation = self.equation
        residual = equation.residual(phi, history)
        failing = residual.abs() > self.tolerance
        self.residual_before, self.failing_fraction = torch.stack([residual.abs().max(), failing.double().mean()]).tolist()
        self.t_check = time.perf_counter() - started
        started = time.perf_counter()
        corrected = torch.zeros(history.shape, dtype=torch.bool, device=self.device)
        self.solve_iterations, self.solve_work = 0, 0.0
        margin, size = self.margin, history.numel()
        for _ in range(self.max_rounds):
            box = _bounding_box(failing, margin)
            if box is None:
                break
            if box_area(box) > self.global_fraction * size:
                box = (slice(0, history.shape[0]), slice(0, history.shape[1]))
            _, iterations = equation.solve_box(phi, history, box, self.solve_fraction * self.tolerance)
            self.solve_iterations += iterations
            self.solve_work += iterations * box_area(box) / size
            corrected[box] = True
            residual = equation.residual(phi, history)
            failing = residual.abs() > self.tolerance
            margin *= 2
        self.residual_after, self.corrected_fraction = torch.stack([residual.abs().max(), corrected.double().mean()]).tolist()
        out = phi.cpu().numpy()   # down once
        self.t_correction = time.perf_counter() - started
        self.phi = phi
        return out
