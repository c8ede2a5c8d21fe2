"""The pixel equation in numpy (and the compiled kernel where it builds): the residual and its
certificate, box solves by multigrid-preconditioned conjugate gradients, the whole image's exact
solve, the Gaussian smoothing of a phase-field image, and the boxes the verified step corrects.

The equation and its coefficients: :mod:`ifenn.pixel_equation.definition`. Written as A phi = 2 H,
A is symmetric positive definite and a strictly diagonally dominant M-matrix (off-diagonal
entries -D w_ij <= 0, every row sum at least a_i; a slit's cut takes the same weight off an
off-diagonal entry and off the diagonal), so the normalised residual r = R / a bounds the error
in the max norm: max_i |phi_i - phi*_i| <= max_i |r_i| (docs/method.md, "The verified step").
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.fft
import scipy.ndimage
import scipy.sparse
import scipy.sparse.linalg

from ifenn.errors import SolverDivergedError
from ifenn.pixel_equation.definition import PixelOperator, edges_of, level_shapes
from ifenn.pixels import LAPLACIAN_CENTRE_WEIGHT, LAPLACIAN_K9_STAR, Box, SlitCuts, grow_box


def compiled_kernel():
    """The compiled pixel kernels (``orbit_kernel.cpp``: the residual and the multigrid-preconditioned
    correction), or None where they do not build (the numpy paths then run)."""
    from ifenn.network.orbit_kernel import load

    return load()


# --------------------------------------------------------------------------- the whole image
@functools.lru_cache(maxsize=16)
def laplacian_matrix(ny: int, nx: int, padding: str = "zeros") -> scipy.sparse.csc_matrix:
    """Sparse K9* - 3 I on an (ny, nx) grid, row-major pixel numbering, without 1/h_px^2.

    "zeros": neighbours beyond the image are dropped (phi = 0 there); "replicate": they
    are folded back onto the nearest edge pixel (zero flux). Cached per shape and padding.
    """
    if padding not in ("zeros", "replicate"):
        raise ValueError("the exact pixel solver supports padding 'zeros' or 'replicate'")
    iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    rows, cols, vals = [], [], []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            weight = LAPLACIAN_K9_STAR[dy + 1, dx + 1]
            if weight == 0.0:
                continue
            jy, jx = iy + dy, ix + dx
            if padding == "replicate":
                jy, jx = np.clip(jy, 0, ny - 1), np.clip(jx, 0, nx - 1)
                inside = np.ones_like(jy, dtype=bool)
            else:
                inside = (jy >= 0) & (jy < ny) & (jx >= 0) & (jx < nx)
            rows.append((iy * nx + ix)[inside])
            cols.append((jy * nx + jx)[inside])
            vals.append(np.full(inside.sum(), weight))
    n = ny * nx
    neighbours = scipy.sparse.csc_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )
    return (neighbours + LAPLACIAN_CENTRE_WEIGHT * scipy.sparse.identity(n, format="csc")).tocsc()


@functools.lru_cache(maxsize=16)
def laplacian_symbol(ny: int, nx: int, padding: str) -> np.ndarray:
    """Eigenvalues of K9* - 3 I in the basis of the fast transform of ``fast_transforms``.

    K9* = (S_x + S_y)/2 + S_x S_y / 4 with S the 1-D sum of the two neighbours; with
    "replicate" S has the DCT-II eigenvalues 2 cos(pi k / n) (exact for the matrix), with
    "zeros" the DST-II ones 2 cos(pi (k + 1) / n) (a close preconditioner: DST-II puts the
    zero half a pixel nearer than the matrix does). Shape (ny, nx).
    """
    shift = 1 if padding == "zeros" else 0
    s_y = 2.0 * np.cos(np.pi * (np.arange(ny) + shift) / ny)[:, None]
    s_x = 2.0 * np.cos(np.pi * (np.arange(nx) + shift) / nx)[None, :]
    return 0.5 * (s_x + s_y) + 0.25 * s_x * s_y + LAPLACIAN_CENTRE_WEIGHT


def fast_transforms(padding: str):
    if padding == "zeros":
        return (lambda v: scipy.fft.dstn(v, type=2, norm="ortho"), lambda v: scipy.fft.idstn(v, type=2, norm="ortho"))
    return (lambda v: scipy.fft.dctn(v, type=2, norm="ortho"), lambda v: scipy.fft.idctn(v, type=2, norm="ortho"))


def solve_pixel_equation(
    history: np.ndarray,
    Gc: float,
    lc: float,
    h_px: float,
    padding: str = "zeros",
    rtol: float = 1e-10,
    maxiter: int = 1000,
    initial_guess: np.ndarray | None = None,
    cuts=None,
) -> np.ndarray:
    """Exact phi of the pixel equation R(phi) = 0 for a history map (no network).

    The equation is linear in phi: A phi = 2H with A = diag(Gc/lc + 2H) - (Gc lc / h_px^2) L
    and L the cached K9* - 3 I matrix; A is symmetric positive definite. It is solved by
    conjugate gradients to relative residual ``rtol``, preconditioned with the exact
    inverse of the constant-coefficient operator min(Gc/lc + 2H) I - (Gc lc / h_px^2) L,
    applied with a fast cosine (replicate) or sine (zeros) transform: 15-45 iterations for
    a 400x400 snt1 map (Jacobi needs ~270).

    history : (ny, nx) or (n, ny, nx) array, N/mm^2 (pass it capped if the network is).
    initial_guess : optional phi of the same shape (e.g. the previous increment's);
        default: the local solution 2H / (Gc/lc + 2H).
    cuts : the stencil links the scene's slits cut (:class:`ifenn.pixels.SlitCuts`), left out
        of L (no flux across a slit, as FEM's doubled nodes); the preconditioner stays the
        uncut operator's (CG then needs a few more iterations).
    Returns phi with the shape of ``history`` (float64).
    """
    history = np.asarray(history, dtype=np.float64)
    if history.ndim == 3:
        guesses = [None] * len(history) if initial_guess is None else list(initial_guess)
        return np.stack(
            [solve_pixel_equation(h, Gc, lc, h_px, padding, rtol, maxiter, g, cuts) for h, g in zip(history, guesses, strict=True)]
        )
    ny, nx = history.shape
    h_flat = history.reshape(-1)
    diffusion = Gc * lc / h_px**2
    reaction = Gc / lc + 2.0 * h_flat
    laplacian = laplacian_matrix(ny, nx, padding)
    if cuts:
        laplacian = laplacian - cuts.matrix()
    system = (scipy.sparse.diags(reaction) - diffusion * laplacian).tocsr()
    rhs = 2.0 * h_flat
    symbol = reaction.min() - diffusion * laplacian_symbol(ny, nx, padding)
    forward, inverse = fast_transforms(padding)
    preconditioner = scipy.sparse.linalg.LinearOperator(
        system.shape, matvec=lambda r: inverse(forward(r.reshape(ny, nx)) / symbol).reshape(-1), dtype=np.float64
    )
    start = rhs / reaction if initial_guess is None else np.asarray(initial_guess, dtype=np.float64).reshape(-1)
    phi, info = scipy.sparse.linalg.cg(system, rhs, x0=start, rtol=rtol, atol=0.0, maxiter=maxiter, M=preconditioner)
    if info != 0:
        raise RuntimeError(f"pixel phase-field CG did not converge in {maxiter} iterations")
    return phi.reshape(ny, nx)


def gaussian_smoothing(
    phi: np.ndarray, sigma: float = 2.0, truncate: float = 4.0, mode: str = "reflect"
) -> np.ndarray:
    """The released script's Gaussian filter: scipy.ndimage.gaussian_filter of each map.

    phi : (ny, nx) or (n, ny, nx); sigma in pixels (default 2); truncate in sigmas (scipy's
    default 4, radius 8 pixels for sigma 2); mode : scipy boundary mode (default "reflect",
    scipy's default). Returns the smoothed maps, same shape.
    """
    phi = np.asarray(phi, dtype=np.float64)
    per_axis_sigma = (0.0,) * (phi.ndim - 2) + (sigma, sigma)
    return scipy.ndimage.gaussian_filter(phi, per_axis_sigma, truncate=truncate, mode=mode)


# --------------------------------------------------------------------------- residuals and box solves
def _stencil_sum(padded: np.ndarray) -> np.ndarray:
    """K9*(x) of the interior of a once-padded array (n + 2, m + 2) -> (n, m)."""
    edge = padded[1:-1, :-2] + padded[1:-1, 2:] + padded[:-2, 1:-1] + padded[2:, 1:-1]
    corner = padded[:-2, :-2] + padded[:-2, 2:] + padded[2:, :-2] + padded[2:, 2:]
    return LAPLACIAN_K9_STAR[0, 1] * edge + LAPLACIAN_K9_STAR[0, 0] * corner


def normalised_residual(phi, history, Gc, lc, h_px, padding="replicate", cuts: SlitCuts | None = None) -> np.ndarray:
    """r = R / (Gc/lc + 2H) on the whole image: an upper bound, in the max norm, of
    |phi - exact| (module doc). R is the residual of :func:`ifenn.pixel_equation.torch_backend.residual`,
    with the stencil links that ``cuts`` (the scene's slits) cut left out."""
    phi, history = np.asarray(phi, dtype=np.float64), np.asarray(history, dtype=np.float64)
    return PixelEquation(Gc, lc, h_px, padding, cuts).residual_on(phi, history, (slice(0, phi.shape[0]), slice(0, phi.shape[1])))


class PixelEquation(PixelOperator):
    """The pixel equation of one image: residuals and local solves on boxes. ``cuts``: the
    stencil links the scene's slits cut (:class:`ifenn.pixels.SlitCuts`; None: no slit)."""

    def __init__(self, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts: SlitCuts | None = None,
                 model=None):
        super().__init__(Gc, lc, h_px, padding, cuts, model)
        self._coarse_cache: dict = {}   # box -> the coarse levels' cut links (_level_links)

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
        out = self.reaction(history) * centre - self.diffusion * (_stencil_sum(ext) - 3.0 * centre)
        return out - 2.0 * history if with_rhs else out

    def residual_on(self, phi: np.ndarray, history: np.ndarray, box: Box, normalised: bool = True) -> np.ndarray:
        """Residual on ``box`` (its own shape): r = R / (Gc/lc + 2H), or R itself; in one pass of
        the compiled kernel where it builds (read from the image: no padded copy), else in numpy;
        the slits' cut links are then taken out (R += D x their flux)."""
        if self.cuts is None:
            return self._residual_uncut(phi, history, box, normalised)
        residual = self._residual_uncut(phi, history, box, False) + self.diffusion * self.cuts.flux_on(phi, box)
        return residual / self.reaction(history[box]) if normalised else residual

    def _residual_uncut(self, phi: np.ndarray, history: np.ndarray, box: Box, normalised: bool) -> np.ndarray:
        lib = compiled_kernel()
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
        return residual / self.reaction(h) if normalised else residual

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
        n, m = box[0].stop - box[0].start, box[1].stop - box[1].start
        if (n, m) == tuple(shape):
            symbol = reaction.min() - self.diffusion * laplacian_symbol(n, m, self.padding)
            forward, inverse = fast_transforms(self.padding)
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
            shapes = level_shapes((box[0].stop - box[0].start, box[1].stop - box[1].start))
            levels = [self.cuts.coarse_links(box, k, shape) for k, shape in enumerate(shapes[1:], start=1)]
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
        edges = edges_of(box, phi.shape)
        h = np.ascontiguousarray(history[box])
        reaction = self.reaction(h)
        links = self.cuts.in_box(box) if self.cuts is not None else None
        lib = compiled_kernel()
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


def bounding_box(mask: np.ndarray, grow: int) -> Box | None:
    """The bounding box of ``mask``'s pixels grown by ``grow`` (clipped), None if empty."""
    rows, cols = np.nonzero(np.any(mask, axis=1))[0], np.nonzero(np.any(mask, axis=0))[0]
    if rows.size == 0:
        return None
    return grow_box((slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)), grow, mask.shape)


def dilated(mask: np.ndarray, by: int) -> np.ndarray:
    """``mask`` grown by ``by`` pixels (square), computed on its bounding box only."""
    crop = bounding_box(mask, by)
    out = np.zeros_like(mask)
    if crop is not None and by > 0:  # a square's maximum filter is separable: O(pixels), whatever ``by``
        out[crop] = scipy.ndimage.maximum_filter(mask[crop].view(np.uint8), size=2 * by + 1, mode="constant") > 0
    elif crop is not None:
        out[crop] = mask[crop]
    return out


def correction_boxes(mask: np.ndarray, margin: int) -> list[Box]:
    """Bounding boxes of the connected groups of ``mask`` grown by at least ``margin`` pixels;
    boxes that overlap are merged.

    Computed on blocks of b = margin // 8 pixels (b = 1 for small margins): a block is set
    where any of its pixels is, the blocks are grown by ceil(margin / b) and grouped, and each
    group's box is taken back to pixels. Every pixel within ``margin`` of a set pixel lies in
    a box (the boxes exceed the exact ones by less than 2 b on each side), at 1 / b^2 of the
    cost: the dilation of a large mask by a margin of 6 lc otherwise costs about as much as a
    multigrid iteration of the correction."""
    crop = bounding_box(mask, margin)
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

