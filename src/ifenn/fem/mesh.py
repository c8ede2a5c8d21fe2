"""Structured Q1 meshes of rectangular scenes, minus their cut-outs, with slit notches cut along
mesh lines.

A slit is made by duplicating the nodes on the notch's element edges: the elements on
one side (above a horizontal slit, right of a vertical one) use the twins, so the two
faces separate under load. Tip nodes inside the domain are shared (not duplicated). This
is how the paper's meshes are built: 201 x 201 nodes + 60 twins for snt1. The cells inside a
cut-out (``ifenn.geometry``) are left out, and so are the nodes no cell uses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ifenn import geometry
from ifenn.geometry import on_grid
from ifenn.io import atomic_path, reading


@dataclass
class StructuredMesh:
    """A structured quadrilateral mesh with slit twins.

    points: (n_nodes, 2) coordinates, mm; the first ``n_grid_nodes`` are the grid nodes in
    row-major order (index j*(nx+1)+i without a cut-out), the twins follow. cells: (n_cells, 4)
    node indices in counter-clockwise (VTK/meshio) order, row-major over the solid cells (cell
    (i, j) at row j*nx+i without a cut-out).
    """

    points: np.ndarray
    cells: np.ndarray
    nx: int
    ny: int
    origin: tuple[float, float]
    h: float
    slits: list[dict] = field(default_factory=list)  # snapped segments and twin counts
    n_grid_nodes: int = -1   # grid nodes (not twins) kept; -1: all (nx + 1)(ny + 1)

    def __post_init__(self) -> None:
        if self.n_grid_nodes < 0:
            self.n_grid_nodes = (self.nx + 1) * (self.ny + 1)

    def metadata(self) -> dict:
        return {
            "nx": self.nx, "ny": self.ny, "origin": list(self.origin), "h": self.h,
            "n_nodes": int(len(self.points)), "n_grid_nodes": self.n_grid_nodes,
            "n_twins": int(len(self.points) - self.n_grid_nodes), "slits": self.slits,
        }


def element_size(scene: dict) -> float:
    """Edge length h (mm) of the square elements of a scene; raises if not square."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    nx, ny = scene["elements"]
    hx, hy = (x1 - x0) / nx, (y1 - y0) / ny
    if abs(hx - hy) > 1e-9 * hx:
        raise ValueError(
            f"elements {scene['elements']} on domain {scene['domain']} give {hx:g} x {hy:g} mm "
            "elements; the pixel map needs square elements"
        )
    return hx


def grid_line(value: float, origin: float, h: float, n: int) -> int:
    """The index of the mesh line nearest ``value`` (mm) on a grid of ``n`` cells of size ``h`` from ``origin``."""
    return int(min(max(round((value - origin) / h), 0), n))


def build_mesh(scene: dict) -> StructuredMesh:
    """Structured Q1 mesh of ``scene`` (config entry) with its slit notches cut in."""
    x0, y0 = scene["domain"]["x"][0], scene["domain"]["y"][0]
    nx, ny = scene["elements"]
    h = element_size(scene)
    ii, jj = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1))
    points = np.column_stack([x0 + ii.ravel() * h, y0 + jj.ravel() * h])
    ci, cj = np.meshgrid(np.arange(nx), np.arange(ny))
    ci, cj = ci.ravel(), cj.ravel()

    def node(i, j):
        return j * (nx + 1) + i

    cells = np.column_stack([node(ci, cj), node(ci + 1, cj), node(ci + 1, cj + 1), node(ci, cj + 1)])
    twins: list[np.ndarray] = []
    slits = []
    used: set[int] = set()
    for notch in scene.get("notches", []):
        if notch["kind"] != "slit":
            continue
        (sx, sy), (ex, ey) = notch["start"], notch["end"]
        off_grid = [c for c, o in ((sx, x0), (sy, y0), (ex, x0), (ey, y0)) if not on_grid(c, o, h)]
        if off_grid and not notch.get("snap", False):
            raise ValueError(f"slit {notch} has coordinates {off_grid} between mesh lines (h = {h:g} mm); "
                             "it is snapped only with 'snap: true'")
        horizontal = abs(sy - ey) <= abs(sx - ex)
        if horizontal:
            line = grid_line(sy, y0, h, ny)
            a, b = sorted((grid_line(sx, x0, h, nx), grid_line(ex, x0, h, nx)))
            n_line, n_along = ny, nx
        else:
            line = grid_line(sx, x0, h, nx)
            a, b = sorted((grid_line(sy, y0, h, ny), grid_line(ey, y0, h, ny)))
            n_line, n_along = nx, ny
        if line in (0, n_line):
            raise ValueError(f"slit {notch} lies on the domain boundary")
        if b == a:
            raise ValueError(f"slit {notch} is shorter than one element (h = {h:g} mm)")
        # Nodes on the slit; a tip inside the domain stays shared.
        along = np.arange(a if a == 0 else a + 1, b + 1 if b == n_along else b)
        ids = node(along, line) if horizontal else node(line, along)
        if used.intersection(ids.tolist()):
            raise ValueError(f"slit {notch} crosses or touches another slit")
        used.update(ids.tolist())
        twin_ids = len(points) + sum(len(t) for t in twins) + np.arange(len(ids))
        twins.append(ids)
        twin_of = dict(zip(ids.tolist(), twin_ids.tolist(), strict=False))
        # Elements on the upper (horizontal) / right (vertical) side use the twins.
        side = (cj == line) & (ci >= a) & (ci < b) if horizontal else (ci == line) & (cj >= a) & (cj < b)
        cells[side] = np.vectorize(twin_of.get, otypes=[np.int64])(cells[side], cells[side])
        snapped = (
            [[x0 + a * h, y0 + line * h], [x0 + b * h, y0 + line * h]] if horizontal
            else [[x0 + line * h, y0 + a * h], [x0 + line * h, y0 + b * h]]
        )
        slits.append({"requested": [notch["start"], notch["end"]], "snapped": snapped, "n_twins": int(len(ids))})
    if twins:
        points = np.vstack([points, points[np.concatenate(twins)]])
    n_grid_nodes = (nx + 1) * (ny + 1)
    if scene.get("cutouts"):
        centres = points[cells].mean(axis=1)
        cells = cells[~geometry.in_cutout(scene, centres[:, 0], centres[:, 1])]
        used = np.unique(cells)
        renumber = np.full(len(points), -1, dtype=np.int64)
        renumber[used] = np.arange(len(used))
        points, cells = points[used], renumber[cells]
        n_grid_nodes = int((used < (nx + 1) * (ny + 1)).sum())
    return StructuredMesh(points, cells.astype(np.int64), nx, ny, (x0, y0), h, slits, n_grid_nodes)


def write_mesh(mesh: StructuredMesh, xdmf_path: str | Path) -> None:
    """Write the mesh with meshio as XDMF + HDF5 (the grid is named 'Grid') and a JSON
    sidecar ``<stem>.json`` with its metadata; each file appears complete or not at all."""
    import meshio

    xdmf_path = Path(xdmf_path)
    xdmf_path.parent.mkdir(parents=True, exist_ok=True)
    # meshio names the HDF5 file after the XDMF file, so write both under a temporary stem
    # in the same folder, then fix the reference and rename.
    tmp_stem = xdmf_path.with_name(f".tmp-{xdmf_path.stem}")
    meshio.write(tmp_stem.with_suffix(".xdmf"), meshio.Mesh(mesh.points, [("quad", mesh.cells)]))
    text = tmp_stem.with_suffix(".xdmf").read_text().replace(tmp_stem.with_suffix(".h5").name, xdmf_path.with_suffix(".h5").name)
    tmp_stem.with_suffix(".h5").replace(xdmf_path.with_suffix(".h5"))
    with atomic_path(xdmf_path) as tmp:
        Path(tmp).write_text(text)
    tmp_stem.with_suffix(".xdmf").unlink()
    with atomic_path(xdmf_path.with_suffix(".json")) as tmp:
        Path(tmp).write_text(json.dumps(mesh.metadata(), indent=1))


def read_metadata(xdmf_path: str | Path) -> dict:
    return json.loads(Path(xdmf_path).with_suffix(".json").read_text())


def read_dolfinx_mesh(xdmf_path: str | Path, comm=None):
    """Read a mesh written by ``write_mesh`` into dolfinx (distributed over ``comm``)."""
    from dolfinx import io
    from mpi4py import MPI

    if not Path(xdmf_path).exists():
        raise FileNotFoundError(f"no mesh file {xdmf_path}")
    with reading(f"{xdmf_path} (with its .h5)", "mesh"), io.XDMFFile(comm or MPI.COMM_WORLD, str(xdmf_path), "r") as stream:
        return stream.read_mesh(name="Grid")
