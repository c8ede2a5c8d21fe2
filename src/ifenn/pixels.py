"""Gauss point <-> pixel maps, and the slits the pixel grid must not see through.

An nx x ny element mesh gives a (2 ny) x (2 nx) image with pixel size h_px = h / 2; each
Gauss point maps to the pixel that contains it (floor of coordinate over h_px). Images are
indexed [iy, ix]: row 0 is the bottom of the domain (y increasing with the row index).

Slits (:class:`SlitCuts`): the FEM mesh gives a slit notch's two faces separate nodes, so no
flux crosses it; the pixel equation's 9-point Laplacian must do the same, or damage on one face
leaks to the other (under shear the notch tip came out 18 % too weak). Every pixel operator
(the residual and its check, the exact solver, the correction) subtracts the stencil links a
slit cuts, taken from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PixelGrid:
    x0: float
    y0: float
    h_px: float
    nx_px: int
    ny_px: int

    @classmethod
    def for_scene(cls, scene: dict) -> PixelGrid:
        (x0, x1), (y0, _) = scene["domain"]["x"], scene["domain"]["y"]
        nx, ny = scene["elements"]
        return cls(float(x0), float(y0), (x1 - x0) / nx / 2.0, 2 * nx, 2 * ny)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.ny_px, self.nx_px)

    def pixel_index(self, coordinates: np.ndarray) -> np.ndarray:
        """Flat pixel index (iy * nx_px + ix) of points ``coordinates[..., 2]`` (mm)."""
        ix = np.clip(np.floor((coordinates[..., 0] - self.x0) / self.h_px), 0, self.nx_px - 1).astype(np.int64)
        iy = np.clip(np.floor((coordinates[..., 1] - self.y0) / self.h_px), 0, self.ny_px - 1).astype(np.int64)
        return iy * self.nx_px + ix

    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """x (nx_px,) and y (ny_px,) coordinates of pixel centres, mm."""
        return (self.x0 + (np.arange(self.nx_px) + 0.5) * self.h_px, self.y0 + (np.arange(self.ny_px) + 0.5) * self.h_px)

    def image_from(self, index: np.ndarray, values: np.ndarray, solid: np.ndarray | None = None) -> np.ndarray:
        """Scatter values at flat pixel indices into an image; every pixel must be hit once, or
        every pixel of the ``solid`` mask (the others, in a cut-out, are 0)."""
        image = np.full(self.nx_px * self.ny_px, np.nan)
        if solid is not None:
            image[~np.ravel(solid)] = 0.0
        image[index] = values
        expected = image.size if solid is None else int(np.count_nonzero(solid))
        if len(index) != expected or np.isnan(image).any():
            raise ValueError(f"Gauss points do not cover the {self.shape} pixel grid's solid one-to-one")
        return image.reshape(self.shape)

    def attrs(self) -> dict:
        return {"x0": self.x0, "y0": self.y0, "h_px": self.h_px, "nx_px": self.nx_px, "ny_px": self.ny_px}


# Boxes on pixel images: (row slice, column slice) with non-negative start and stop.
Box = tuple[slice, slice]


def _stencil_neighbours(shape: tuple[int, int], padding: str):
    """Per stencil link (dy, dx, weight): pixel indices (iy, ix), its neighbour (jy, jx) as the
    padding reads it, and which links exist (replicate: folded onto the edge pixel, none onto the
    pixel itself, which carries nothing; zeros: none beyond the image)."""
    ny, nx = shape
    iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    for dy, dx, weight in STENCIL_LINKS:
        jy, jx = iy + dy, ix + dx
        if padding == "replicate":
            jy, jx = np.clip(jy, 0, ny - 1), np.clip(jx, 0, nx - 1)
            valid = (jy != iy) | (jx != ix)
        else:
            valid = (jy >= 0) & (jy < ny) & (jx >= 0) & (jx < nx)
            jy, jx = np.clip(jy, 0, ny - 1), np.clip(jx, 0, nx - 1)
        yield dy, dx, weight, iy, ix, jy, jx, valid


def grow_box(box: Box, by: int, shape: tuple[int, int]) -> Box:
    """``box`` grown by ``by`` pixels on every side, clipped to an image of ``shape``."""
    return tuple(slice(max(side.start - by, 0), min(side.stop + by, n)) for side, n in zip(box, shape, strict=True))


def box_within(box: Box, crop: Box) -> Box:
    """``box`` in the coordinates of the crop ``crop`` (which holds it)."""
    return tuple(slice(side.start - c.start, side.stop - c.start) for side, c in zip(box, crop, strict=True))


def box_area(box: Box) -> int:
    return (box[0].stop - box[0].start) * (box[1].stop - box[1].start)


# --------------------------------------------------------------------------- slits
#: Laplacian stencil K9* of the paper (section "PICNN training"); its weights sum to 3.
LAPLACIAN_K9_STAR = np.array([[0.25, 0.5, 0.25], [0.5, 0.0, 0.5], [0.25, 0.5, 0.25]])
#: Weight of the centre pixel in Lap(phi) * h_px^2 (= -sum of K9*).
LAPLACIAN_CENTRE_WEIGHT = -3.0
#: K9*'s links to the 8 neighbours, (dy, dx, weight): the Laplacian is
#: sum over links of w (phi_j - phi_i) / h_px^2
STENCIL_LINKS = tuple((dy, dx, float(LAPLACIAN_K9_STAR[dy + 1, dx + 1])) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0))


@dataclass(frozen=True)
class SlitCuts:
    """The stencil links of a pixel image that cross a slit, as directed links i -> j (flat
    indices, row-major) with their stencil weight w: the Laplacian with the slits is

        Lap_cut(phi)_i = Lap(phi)_i - sum_{cut links i -> j} w (phi_j - phi_i) / h_px^2.

    A link is cut when the segment between the two pixel centres crosses a slit segment
    strictly (a link through a slit's tip is not: the material around the tip is whole, as the
    FEM mesh shares the tip node). With "replicate" padding (zero flux at the image edge) a
    link to a pixel beyond the edge reads the edge pixel it is folded onto, and is cut like
    any other (a slit that starts on the domain's boundary is extended beyond it); with "zeros"
    padding links beyond the image carry no neighbour and are left alone. Both directions of a
    link are listed, so the cut operator stays symmetric.

    Cutting links keeps the pixel operator A = diag(Gc/lc + 2H) - (Gc lc / h_px^2) Lap_cut an
    M-matrix with row sums >= Gc/lc + 2H: each cut removes w from an off-diagonal entry and
    the same w from the diagonal (ifenn.hybrid.verification's bound holds unchanged)."""

    shape: tuple[int, int]
    rows: np.ndarray = field(repr=False)
    cols: np.ndarray = field(repr=False)
    weights: np.ndarray = field(repr=False)
    #: (grid, slits, domain) of :meth:`from_slits`: what :meth:`coarse_links` redraws at coarser spacings
    source: tuple | None = field(default=None, repr=False, compare=False)

    @classmethod
    def none(cls, shape: tuple[int, int]) -> SlitCuts:
        empty = np.zeros(0, dtype=np.int64)
        return cls(tuple(shape), empty, empty, np.zeros(0))

    @classmethod
    def for_scene(cls, scene: dict, grid: PixelGrid, padding: str = "replicate") -> SlitCuts:
        """The cuts of ``scene``'s slit notches (config entries of kind 'slit') on ``grid``, and
        of its cut-outs (``ifenn.geometry``): every link between a solid pixel and a removed one,
        those through a cut-out's corner included. The cut-outs' edges are also drawn as slits, so
        that the coarse multigrid levels (:meth:`coarse_links`) see them at their spacing."""
        from ifenn import geometry

        slits = [(notch["start"], notch["end"]) for notch in scene.get("notches", []) if notch["kind"] == "slit"]
        cuts = cls.from_slits(grid, slits, padding, scene["domain"])
        if not scene.get("cutouts"):
            return cuts
        # the coarse levels redraw the cut-outs' edges inside the domain as slits
        (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
        edges = []
        for a, b, c, d in geometry.cutouts(scene):
            edges += [e for e, inside in ((((a, c), (b, c)), c > y0), (((b, c), (b, d)), b < x1),
                                          (((b, d), (a, d)), d < y1), (((a, d), (a, c)), a > x0)) if inside]
        source = (grid, tuple(slits) + tuple(edges), scene["domain"])
        solid = geometry.solid_pixels(scene, grid)
        rows, cols, weights = [], [], []
        for _, _, weight, iy, ix, jy, jx, valid in _stencil_neighbours(grid.shape, padding):
            cut = valid & (solid[iy, ix] != solid[jy, jx])
            rows.append((iy * grid.nx_px + ix)[cut])
            cols.append((jy * grid.nx_px + jx)[cut])
            weights.append(np.full(int(cut.sum()), weight))
        rows, cols, weights = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
        # a stencil link may be listed twice (folded links of the replicate padding: their weights
        # add up); a link a slit already cuts is not cut again
        n = grid.nx_px * grid.ny_px
        fresh = ~np.isin(rows * n + cols, cuts.rows * n + cuts.cols)
        return cls(tuple(grid.shape), np.concatenate([cuts.rows, rows[fresh]]).astype(np.int64),
                   np.concatenate([cuts.cols, cols[fresh]]).astype(np.int64), np.concatenate([cuts.weights, weights[fresh]]), source)

    @classmethod
    def from_slits(cls, grid: PixelGrid, slits, padding: str = "replicate", domain: dict | None = None) -> SlitCuts:
        """Cuts of slit segments ``slits`` [((x, y), (x, y)), ...] (mm) on ``grid``. An end on
        the boundary of ``domain`` ({'x': [x0, x1], 'y': [y0, y1]}) is extended beyond it."""
        if padding not in ("replicate", "zeros"):
            raise ValueError(f"slit cuts need padding 'replicate' or 'zeros', got {padding!r}")
        ny, nx = grid.shape
        if not slits:
            return cls.none(grid.shape)
        h = grid.h_px
        tol = 1e-9 * h
        rows, cols, weights = [], [], []
        for dy, dx, weight, iy, ix, jy, jx, valid in _stencil_neighbours(grid.shape, padding):
            px, py = grid.x0 + (ix + 0.5) * h, grid.y0 + (iy + 0.5) * h
            qx, qy = px + dx * h, py + dy * h   # the neighbour where the link points, before any folding
            crossed = np.zeros(grid.shape, dtype=bool)
            for start, end in slits:
                (sx, sy), (ex, ey) = _extended_slit(start, end, domain, 2.0 * h)
                tx, ty = (ex - sx), (ey - sy)
                length = np.hypot(tx, ty)
                # signed distances (mm): of the link's ends from the slit's line, of the slit's ends
                # from the link's line; a strict crossing has both pairs on opposite sides
                side_p = (tx * (py - sy) - ty * (px - sx)) / length
                side_q = (tx * (qy - sy) - ty * (qx - sx)) / length
                lx, ly = qx - px, qy - py
                link = np.hypot(lx, ly)
                side_s = (lx * (sy - py) - ly * (sx - px)) / link
                side_e = (lx * (ey - py) - ly * (ex - px)) / link
                crossed |= _opposite(side_p, side_q, tol) & _opposite(side_s, side_e, tol)
            cut = crossed & valid
            rows.append((iy * nx + ix)[cut])
            cols.append((jy * nx + jx)[cut])
            weights.append(np.full(int(cut.sum()), weight))
        return cls(grid.shape, np.concatenate(rows).astype(np.int64), np.concatenate(cols).astype(np.int64), np.concatenate(weights),
                   (grid, tuple(slits), domain))

    def coarse_links(self, box: Box, level: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cut links of a multigrid level over ``box``: cells of 2^level x 2^level pixels from
        the box's corner (``shape`` cells), the slits redrawn at that spacing; links to cells
        beyond the box are not cut (zero padding: the level's operator stays symmetric). Where a
        slit's line runs through a level's cells (both faces in one cell) nothing is cut there:
        re-discretised levels cannot split a cell. Empty where the cuts were not drawn from slits
        (a crop, a batch)."""
        if self.source is None or not self:
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty, np.zeros(0)
        grid, slits, domain = self.source
        scale = 2**level
        coarse = PixelGrid(grid.x0 + box[1].start * grid.h_px, grid.y0 + box[0].start * grid.h_px, grid.h_px * scale,
                           int(shape[1]), int(shape[0]))
        cuts = SlitCuts.from_slits(coarse, list(slits), "zeros", domain)
        return cuts.rows, cuts.cols, cuts.weights

    def __bool__(self) -> bool:
        return self.rows.size > 0

    def flux(self, phi: np.ndarray) -> np.ndarray:
        """sum over the cut links i -> j of w (phi_j - phi_i) at each pixel i (ny, nx): what
        the slits take out of K9*(phi) - 3 phi."""
        return self.flux_on(phi, (slice(0, self.shape[0]), slice(0, self.shape[1])))

    def flux_on(self, phi: np.ndarray, box: Box) -> np.ndarray:
        """:meth:`flux` on ``box`` only (the box's shape), phi read from the whole image."""
        out = np.zeros((box[0].stop - box[0].start, box[1].stop - box[1].start))
        if not self:
            return out
        nx = self.shape[1]
        ry, rx = self.rows // nx, self.rows % nx
        inside = (ry >= box[0].start) & (ry < box[0].stop) & (rx >= box[1].start) & (rx < box[1].stop)
        if inside.any():
            flat = np.asarray(phi, dtype=np.float64).reshape(-1)
            rows, cols = self.rows[inside], self.cols[inside]
            local = (ry[inside] - box[0].start) * out.shape[1] + (rx[inside] - box[1].start)
            np.add.at(out.reshape(-1), local, self.weights[inside] * (flat[cols] - flat[rows]))
        return out

    def matrix(self):
        """The cut links' part of the sparse K9* - 3 I (n x n, csc): subtract it for the slits."""
        import scipy.sparse

        n = self.shape[0] * self.shape[1]
        links = scipy.sparse.csc_matrix((self.weights, (self.rows, self.cols)), shape=(n, n))
        return (links - scipy.sparse.diags(np.asarray(links.sum(axis=1)).ravel())).tocsc()

    def crop(self, box: Box) -> SlitCuts:
        """The cuts of the image cropped to ``box``: the links with both ends inside it, in the
        crop's indices (a crop whose Laplacian pads at the image's own edge folds as the image)."""
        rows, cols, weights = self.in_box(box)
        inside = cols >= 0
        shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
        return SlitCuts(shape, rows[inside].astype(np.int64), cols[inside].astype(np.int64), weights[inside])

    @staticmethod
    def stacked(cuts: list[SlitCuts]) -> SlitCuts:
        """The cuts of a batch of images of one shape (n, ny, nx), indices into the flattened
        batch: image k's pixel i is k * ny * nx + i (torch's Laplacian of a batch of crops)."""
        shape = cuts[0].shape
        size = shape[0] * shape[1]
        return SlitCuts((len(cuts), *shape), np.concatenate([c.rows + k * size for k, c in enumerate(cuts)]),
                        np.concatenate([c.cols + k * size for k, c in enumerate(cuts)]), np.concatenate([c.weights for c in cuts]))

    def in_box(self, box: Box) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cut links starting inside ``box``, in the box's flat indices: (rows, cols,
        weights), cols -1 where the link's other end lies outside the box."""
        nx = self.shape[1]
        (r0, r1), (c0, c1) = (box[0].start, box[0].stop), (box[1].start, box[1].stop)
        ry, rx, cy, cx = self.rows // nx, self.rows % nx, self.cols // nx, self.cols % nx
        inside = (ry >= r0) & (ry < r1) & (rx >= c0) & (rx < c1)
        width = c1 - c0
        other_inside = (cy >= r0) & (cy < r1) & (cx >= c0) & (cx < c1)
        rows = (ry - r0) * width + (rx - c0)
        cols = np.where(other_inside, (cy - r0) * width + (cx - c0), -1)
        return rows[inside], cols[inside], self.weights[inside]


def _opposite(a, b, tol: float) -> np.ndarray:
    """a and b strictly on opposite sides of zero (beyond ``tol``)."""
    return ((a < -tol) & (b > tol)) | ((a > tol) & (b < -tol))


def _extended_slit(start, end, domain: dict | None, by: float):
    """The slit's ends, each moved ``by`` outwards along the slit where it lies on the
    domain's boundary (so links beyond the image edge, folded back by the padding, are cut)."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    if domain is None:
        return start, end
    direction = (end - start) / np.linalg.norm(end - start)
    (x0, x1), (y0, y1) = domain["x"], domain["y"]
    tol = 1e-9 * max(x1 - x0, y1 - y0)

    def on_boundary(point):
        return min(abs(point[0] - x0), abs(point[0] - x1), abs(point[1] - y0), abs(point[1] - y1)) <= tol

    return (start - by * direction if on_boundary(start) else start), (end + by * direction if on_boundary(end) else end)
