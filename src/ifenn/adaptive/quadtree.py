"""A graded quadrilateral mesh from a level map on a fine grid: a 2:1-balanced quadtree whose
leaves are the cells, with the hanging nodes it makes and the slits it must keep open.

Everything here is integer index arithmetic on the finest grid (numpy only, no dolfinx), so the
mesh of a marked region is rebuilt in milliseconds and is the same on every machine.

The finest grid has ``nx x ny`` cells of size ``h_fine``; ``levels`` = L: a leaf of level l is a
square block of 2^(L - l) fine cells (level 0: the coarsest blocks, level L: one fine cell).
``target`` (ny, nx) says, per fine cell, the level it needs at least; the leaf level of a fine
cell is the smallest l whose level-l block needs no more than l, raised until every two fine
cells that share an edge lie in leaves one level apart at most (2:1 balance). Then every hanging
node is the midpoint of one coarser leaf's edge, tied to its two ends (u_hanging = (u_a +
u_b) / 2): bilinear on that edge, so the displacement is continuous (a conforming Q1 space).

Slits (on the scene's element grid, as :func:`ifenn.fem.mesh.build_mesh`) are kept open
as there: the nodes on a slit are doubled and the leaves on its upper (horizontal) or right
(vertical) side use the twins; a tip inside the domain stays shared. So that no leaf straddles a
slit, the fine cells along it need the level at which the slit's line and ends are block edges;
and leaves face each other across a slit at equal levels, so no node on a slit hangs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: corners of a leaf in dolfinx's (tensor-product) order: (x0, y0), (x1, y0), (x0, y1), (x1, y1)
CORNERS = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])


@dataclass
class FineSlit:
    """A slit on the finest grid: along ``axis`` (0: horizontal, a line y = line; 1: vertical,
    x = line), from ``start`` to ``stop`` (fine-cell units along it)."""

    axis: int
    line: int
    start: int
    stop: int


@dataclass
class Quadtree:
    """Leaves, nodes and constraints of one level map (module doc)."""

    origin: tuple[float, float]
    h_fine: float
    levels: int
    leaf_level: np.ndarray          # (ny, nx) int: the level of the leaf holding each fine cell
    slits: list[FineSlit] = field(default_factory=list)
    #: (ny, nx) bool: fine cells in a cut-out or the padding, whose leaves (never straddling) are left out
    removed: np.ndarray | None = None

    def __post_init__(self):
        self.ny, self.nx = self.leaf_level.shape
        origins, sizes = [], []
        for level in range(self.levels + 1):
            size = 2 ** (self.levels - level)
            iy, ix = np.meshgrid(np.arange(0, self.ny, size), np.arange(0, self.nx, size), indexing="ij")
            leaf = self.leaf_level[iy, ix] == level
            if self.removed is not None:
                leaf &= ~self.removed[iy, ix]
            origins.append(np.column_stack([ix[leaf], iy[leaf]]))
            sizes.append(np.full(int(leaf.sum()), size))
        #: per cell: lower-left corner (fine units, x then y) and edge length (fine cells)
        self.cell_origin = np.concatenate(origins).astype(np.int64)
        self.cell_size = np.concatenate(sizes).astype(np.int64)
        corners = self.cell_origin[:, None, :] + self.cell_size[:, None, None] * CORNERS[None]
        key = corners[..., 1] * (self.nx + 1) + corners[..., 0]
        grid_keys, cells = np.unique(key.ravel(), return_inverse=True)
        self.node_ij = np.column_stack([grid_keys % (self.nx + 1), grid_keys // (self.nx + 1)])
        self.cells = cells.reshape(-1, 4).astype(np.int64)
        node_of_key = np.full((self.nx + 1) * (self.ny + 1), -1, dtype=np.int64)
        node_of_key[grid_keys] = np.arange(len(grid_keys))
        self.hanging, self.masters = self._hanging(node_of_key)
        self.n_grid_nodes = len(grid_keys)
        self._twin_slits(node_of_key)

    # ------------------------------------------------------------------ nodes
    def _hanging(self, node_of_key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes at the midpoint of a leaf's edge, and that edge's two end nodes."""
        big = self.cell_size >= 2
        o, s = self.cell_origin[big], self.cell_size[big]
        half = s // 2
        found_nodes, found_masters = [], []
        # (midpoint offset, end a, end b) per edge, in units of the cell size: bottom, top, left, right
        for mid, a, b in (((1, 0), (0, 0), (2, 0)), ((1, 2), (0, 2), (2, 2)), ((0, 1), (0, 0), (0, 2)), ((2, 1), (2, 0), (2, 2))):
            m = o + half[:, None] * np.array(mid)
            node = node_of_key[m[:, 1] * (self.nx + 1) + m[:, 0]]
            at = node >= 0
            ends = [node_of_key[(o[at] + half[at, None] * np.array(e))[:, 1] * (self.nx + 1) + (o[at] + half[at, None] * np.array(e))[:, 0]]
                    for e in (a, b)]
            found_nodes.append(node[at])
            found_masters.append(np.column_stack(ends))
        nodes, first = np.unique(np.concatenate(found_nodes), return_index=True)
        masters = np.concatenate(found_masters)[first]
        if np.isin(masters, nodes).any():
            raise AssertionError("a hanging node's master hangs: the level map is not 2:1 balanced")
        return nodes.astype(np.int64), masters.astype(np.int64)

    def _twin_slits(self, node_of_key: np.ndarray) -> None:
        """Double the nodes on each slit for the leaves on its upper / right side (module doc)."""
        twins_of: list[np.ndarray] = []
        n = self.n_grid_nodes
        for slit in self.slits:
            along_n = self.nx if slit.axis == 0 else self.ny
            inner = np.arange(slit.start if slit.start == 0 else slit.start + 1, slit.stop + 1 if slit.stop == along_n else slit.stop)
            ix, iy = (inner, np.full_like(inner, slit.line)) if slit.axis == 0 else (np.full_like(inner, slit.line), inner)
            nodes = node_of_key[iy * (self.nx + 1) + ix]
            nodes = nodes[nodes >= 0]
            if np.isin(nodes, self.hanging).any():
                raise AssertionError("a node on a slit hangs: the leaves across it differ in level")
            total = n + sum(len(t) for t in twins_of)
            lookup = np.full(total, -1, dtype=np.int64)
            lookup[nodes] = total + np.arange(len(nodes))
            twins_of.append(nodes)
            o, s = self.cell_origin, self.cell_size
            if slit.axis == 0:
                side = (o[:, 1] == slit.line) & (o[:, 0] >= slit.start) & (o[:, 0] + s <= slit.stop)
            else:
                side = (o[:, 0] == slit.line) & (o[:, 1] >= slit.start) & (o[:, 1] + s <= slit.stop)
            block = self.cells[side]
            swap = lookup[block]
            self.cells[side] = np.where(swap >= 0, swap, block)
            # a hanging node on the twins' side is tied to the twins, not to the other face's nodes
            ij = self.node_ij[self.hanging]
            upper = ij[:, 1 - slit.axis] > slit.line
            tied = self.masters[upper]
            self.masters[upper] = np.where(lookup[tied] >= 0, lookup[tied], tied)
        self.twin_of = np.concatenate(twins_of) if twins_of else np.empty(0, dtype=np.int64)

    @property
    def points(self) -> np.ndarray:
        """(n_nodes, 2) coordinates in mm: the grid nodes, then the slits' twins."""
        ij = np.vstack([self.node_ij, self.node_ij[self.twin_of]]) if self.twin_of.size else self.node_ij
        return np.asarray(self.origin, dtype=float) + self.h_fine * ij

    @property
    def n_nodes(self) -> int:
        return self.n_grid_nodes + len(self.twin_of)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def free_nodes(self) -> np.ndarray:
        """Nodes that carry unknowns (not hanging)."""
        free = np.ones(self.n_nodes, dtype=bool)
        free[self.hanging] = False
        return np.flatnonzero(free)


# --------------------------------------------------------------------------- level maps
def leaf_levels(target: np.ndarray, levels: int) -> np.ndarray:
    """Per fine cell, the smallest l whose level-l block needs no more than l (module doc)."""
    ny, nx = target.shape
    out = np.full(target.shape, levels, dtype=np.int64)
    for level in range(levels - 1, -1, -1):
        size = 2 ** (levels - level)
        block = target.reshape(ny // size, size, nx // size, size).max(axis=(1, 3))
        coarse_enough = np.repeat(np.repeat(block <= level, size, axis=0), size, axis=1)
        out[coarse_enough] = level
    return out


def balanced(target: np.ndarray, levels: int, slits: list[FineSlit] = ()) -> np.ndarray:
    """The leaf levels of ``target`` raised until leaves sharing an edge are one level apart at
    most and leaves face each other across a slit at the same level."""
    target = np.asarray(target, dtype=np.int64).copy()
    sides = [_slit_sides(s, target.shape) for s in slits]
    while True:
        leaf = leaf_levels(target, levels)
        need = np.zeros_like(leaf)
        need[1:, :] = np.maximum(need[1:, :], leaf[:-1, :] - 1)
        need[:-1, :] = np.maximum(need[:-1, :], leaf[1:, :] - 1)
        need[:, 1:] = np.maximum(need[:, 1:], leaf[:, :-1] - 1)
        need[:, :-1] = np.maximum(need[:, :-1], leaf[:, 1:] - 1)
        for below, above in sides:
            both = np.maximum(leaf[below], leaf[above])
            need[below] = np.maximum(need[below], both)
            need[above] = np.maximum(need[above], both)
        raised = np.maximum(target, need)
        if np.array_equal(raised, target):
            return leaf
        target = raised


def _slit_sides(slit: FineSlit, shape: tuple[int, int]) -> tuple[tuple, tuple]:
    """Index tuples of the fine cells on either side of a slit (below / above, or left / right)."""
    along = np.arange(slit.start, slit.stop)
    if slit.axis == 0:
        return (np.full_like(along, slit.line - 1), along), (np.full_like(along, slit.line), along)
    return (along, np.full_like(along, slit.line - 1)), (along, np.full_like(along, slit.line))


def slit_targets(target: np.ndarray, levels: int, slits: list[FineSlit]) -> np.ndarray:
    """``target`` raised along each slit to the level at which its line and its ends are block
    edges, so that no leaf straddles it (module doc)."""
    target = np.asarray(target, dtype=np.int64).copy()
    for slit in slits:
        level = next(lv for lv in range(levels + 1)
                     if all(v % 2 ** (levels - lv) == 0 for v in (slit.line, slit.start, slit.stop)))
        for side in _slit_sides(slit, target.shape):
            target[side] = np.maximum(target[side], level)
    return target


def coarsest_levels(nx: int, ny: int, wanted: int) -> int:
    """The most levels <= ``wanted`` whose coarsest blocks tile an nx x ny fine grid."""
    levels = wanted
    while levels > 0 and (nx % 2**levels or ny % 2**levels):
        levels -= 1
    return levels


def padded_shape(ny: int, nx: int, levels: int) -> tuple[int, int]:
    """The fine grid ny x nx grown at the top and right to whole coarsest blocks (2^levels fine
    cells): the grid a quadtree of ``levels`` levels is built on, the added cells removed (as a
    cut-out's), so that a scene whose grid the coarsest block does not divide still gets them."""
    block = 2**levels
    return -(-ny // block) * block, -(-nx // block) * block


def pad(image: np.ndarray, shape: tuple[int, int], fill) -> np.ndarray:
    """``image`` (ny, nx) in the lower-left corner of an array of ``shape`` filled with ``fill``."""
    out = np.full(shape, fill, dtype=np.asarray(image).dtype)
    out[: image.shape[0], : image.shape[1]] = image
    return out


def pure_levels(removed: np.ndarray, levels: int) -> np.ndarray:
    """Per fine cell, the coarsest level whose block holding it is all removed or all kept: no
    leaf at that level or finer straddles a cut-out's edge."""
    ny, nx = removed.shape
    out = np.full(removed.shape, levels, dtype=np.int64)
    for level in range(levels - 1, -1, -1):   # finer to coarser: a coarse pure block has pure parts
        size = 2 ** (levels - level)
        blocks = removed.reshape(ny // size, size, nx // size, size)
        pure = blocks.all(axis=(1, 3)) | ~blocks.any(axis=(1, 3))
        out[np.repeat(np.repeat(pure, size, axis=0), size, axis=1)] = level
    return out


def build_quadtree(target: np.ndarray, levels: int, origin, h_fine: float, slits: list[FineSlit] = (),
                   removed: np.ndarray | None = None) -> Quadtree:
    """The balanced quadtree of a target level map with its slits (module doc), without the fine
    cells ``removed`` (a cut-out's, or the padding of :func:`padded_shape`): no leaf straddles
    their edge (:func:`pure_levels`; a block wholly removed stays coarse), and their leaves are left
    out of the mesh."""
    slits = list(slits)
    target = np.asarray(target, dtype=np.int64)
    if removed is not None:
        target = np.maximum(target, pure_levels(removed, levels))
    leaf = balanced(slit_targets(target, levels, slits), levels, slits)
    return Quadtree((float(origin[0]), float(origin[1])), float(h_fine), levels, leaf, slits, removed)
