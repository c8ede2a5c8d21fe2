"""Supports and loads of a scene: whole edges, parts of edges, and single nodes.

A scene's ``boundary`` maps

- an edge (``left``, ``right``, ``bottom``, ``top``) to ``{x: fixed|load, y: fixed|load}``: the
  condition on the whole edge;
- or an edge to a list of parts ``[{range: [a, b], x: ..., y: ...}]``: the condition on the nodes
  of the edge whose coordinate along it (x on bottom and top, y on left and right) lies in
  [a, b];
- ``points`` to a list ``[{at: [x, y], x: ..., y: ...}]``: the condition on one mesh node (a pinned
  support fixes x and y, a roller one of them, a point load prescribes ``load``);
- ``segments`` to a list ``[{from: [x, y], to: [x, y], x: ..., y: ...}]``: the condition on a
  horizontal or vertical segment of the solid's boundary that is not on the domain's edges (the
  edge of a cut-out: the L-panel's load).

``fixed`` holds the component at zero, ``load`` prescribes it to the load of the increment (mm),
``-load`` to minus the load (a beam pushed down). The reaction force a run reports is the sum of
the internal forces on the loaded dofs in their loaded direction (N per mm of thickness, times the
scene's thickness). Every part and point lies on mesh nodes: the checks
refuse one that does not (never snapped silently), and a set of supports that leaves a rigid-body
motion free (:func:`problems`).

:func:`conditions` turns a scene into :class:`Condition` objects that select nodes by their
coordinates, so the uniform mesh (dolfinx) and the adaptive quadtree use the same definition.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ifenn import geometry
from ifenn.geometry import on_grid

EDGES = ("left", "right", "bottom", "top")
COMPONENTS = {"x": 0, "y": 1}
#: the kinds that follow the load, with the sign of the prescribed displacement
LOADS = {"load": 1.0, "-load": -1.0}


@dataclass(frozen=True)
class Condition:
    """One prescribed displacement component on a set of boundary nodes."""

    key: str                      # the config key it comes from, for messages
    component: int                # 0: x, 1: y
    kind: str                     # "fixed", "load" or "-load"
    edge: str | None              # the edge it lies on; None for a point
    start: tuple[float, float]    # the part's ends (a point: both the point), mm
    end: tuple[float, float]
    tolerance: float              # mm: a node within it of the part is on it

    def selects(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Which of the nodes at (x, y) this condition holds (boolean mask)."""
        (ax, ay), (bx, by), tol = self.start, self.end, self.tolerance
        return ((x >= min(ax, bx) - tol) & (x <= max(ax, bx) + tol)
                & (y >= min(ay, by) - tol) & (y <= max(ay, by) + tol))

    @property
    def is_point(self) -> bool:
        return self.edge is None


def loaded_dofs(held: list[tuple[np.ndarray, str]]) -> tuple[np.ndarray, np.ndarray]:
    """The loaded dofs of (dofs, kind) pairs, unique and sorted, with the sign of each (+1 ``load``,
    -1 ``-load``: the direction the reported force is counted in); fixed ones are left out."""
    pairs = [(dofs, np.full(len(dofs), LOADS[kind])) for dofs, kind in held if kind in LOADS]
    if not pairs:
        return np.empty(0, dtype=np.int64), np.empty(0)
    dofs, first = np.unique(np.concatenate([d for d, _ in pairs]), return_index=True)
    return dofs, np.concatenate([sign for _, sign in pairs])[first]


def _edge_segment(edge: str, domain: dict, along: tuple[float, float] | None):
    (x0, x1), (y0, y1) = domain["x"], domain["y"]
    if edge in ("bottom", "top"):
        y = y0 if edge == "bottom" else y1
        a, b = along if along is not None else (x0, x1)
        return (a, y), (b, y)
    x = x0 if edge == "left" else x1
    a, b = along if along is not None else (y0, y1)
    return (x, a), (x, b)


def conditions(scene: dict, key: str = "scene") -> list[Condition]:
    """The scene's boundary conditions, one per (part, component), in config order."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    tol = 1e-9 * max(x1 - x0, y1 - y0)
    found = []
    for edge, spec in scene["boundary"].items():
        if edge == "points":
            for i, point in enumerate(spec):
                at = (float(point["at"][0]), float(point["at"][1]))
                found += [Condition(f"{key}.boundary.points[{i}]", COMPONENTS[c], kind, None, at, at, tol)
                          for c, kind in point.items() if c in COMPONENTS]
            continue
        if edge == "segments":
            for i, segment in enumerate(spec):
                start, end = tuple(map(float, segment["from"])), tuple(map(float, segment["to"]))
                found += [Condition(f"{key}.boundary.segments[{i}]", COMPONENTS[c], kind, "segment", start, end, tol)
                          for c, kind in segment.items() if c in COMPONENTS]
            continue
        parts = spec if isinstance(spec, list) else [dict(spec)]
        for i, part in enumerate(parts):
            start, end = _edge_segment(edge, scene["domain"], part.get("range"))
            part_key = f"{key}.boundary.{edge}" + (f"[{i}]" if isinstance(spec, list) else "")
            found += [Condition(part_key, COMPONENTS[c], kind, edge, start, end, tol)
                      for c, kind in part.items() if c in COMPONENTS]
    return found


def problems(scene: dict, key: str) -> list[str]:
    """What is wrong with the scene's supports and loads, one message per problem naming the key:
    a part off its edge or with its ends between mesh nodes, a point off the mesh's nodes, no load,
    or supports that leave a rigid-body motion free."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    nx, ny = scene["elements"]
    h = (x1 - x0) / nx
    found = []
    for edge, spec in scene["boundary"].items():
        if edge == "segments":
            found += _segment_problems(scene, spec, key, h)
            continue
        if edge == "points" or not isinstance(spec, list):
            continue
        low, high = (x0, x1) if edge in ("bottom", "top") else (y0, y1)
        origin = low
        for i, part in enumerate(spec):
            a, b = part["range"]
            pkey = f"config key '{key}.boundary.{edge}[{i}].range'"
            if not (low - 1e-12 <= a < b <= high + 1e-12):
                found.append(f"{pkey}: {part['range']} must be an interval within the edge, [{low}, {high}], with a < b")
            elif not (on_grid(a, origin, h) and on_grid(b, origin, h)):
                found.append(f"{pkey}: its ends {part['range']} must lie on mesh nodes (every {h:g} mm from {origin:g}); "
                             "a support or load between nodes is not snapped: move its ends or change the elements")
    for i, point in enumerate(scene["boundary"].get("points", [])):
        px, py = point["at"]
        pkey = f"config key '{key}.boundary.points[{i}].at'"
        if not (x0 - 1e-12 <= px <= x1 + 1e-12 and y0 - 1e-12 <= py <= y1 + 1e-12):
            found.append(f"{pkey}: {point['at']} lies outside the domain x in [{x0}, {x1}], y in [{y0}, {y1}]")
        elif not (on_grid(px, x0, h) and on_grid(py, y0, h)):
            found.append(f"{pkey}: {point['at']} is not a mesh node (nodes every {h:g} mm from ({x0:g}, {y0:g})); "
                         "a point support is not snapped: move it or change the elements")
    if found:
        return found
    held = conditions(scene, key)
    if not any(c.kind in LOADS for c in held):
        found.append(f"config key '{key}.boundary': no support prescribes 'load'; at least one must")
    # the nodes each condition holds: the mesh's nodes on its part that belong to the solid
    ends = []
    for c in held:
        nodes = _solid_nodes_on(scene, c, h)
        if len(nodes) == 0:
            found.append(f"config key '{c.key}': no node of the mesh lies there (it is inside a cut-out)")
        else:
            ends.append(Condition(c.key, c.component, c.kind, c.edge, tuple(nodes[0]), tuple(nodes[-1]), c.tolerance))
    if found:
        return found
    free = rigid_body_motions_left(ends)
    if free:
        found.append(f"config key '{key}.boundary': the supports leave a rigid-body motion free ({', '.join(free)}); "
                     "fix more components (a pinned point and a roller, or a fixed edge)")
    return found


def _segment_problems(scene: dict, segments: list[dict], key: str, h: float) -> list[str]:
    """Segments must be horizontal or vertical, end on mesh nodes inside the domain, and lie on the
    solid's boundary: solid on exactly one side all along."""

    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    found = []
    for i, segment in enumerate(segments):
        skey = f"config key '{key}.boundary.segments[{i}]'"
        (ax, ay), (bx, by) = segment["from"], segment["to"]
        if (abs(ax - bx) > 1e-12) == (abs(ay - by) > 1e-12):
            found.append(f"{skey}: from {segment['from']} to {segment['to']} must be a horizontal or vertical segment of length > 0")
            continue
        if not all(x0 - 1e-12 <= x <= x1 + 1e-12 for x in (ax, bx)) or not all(y0 - 1e-12 <= y <= y1 + 1e-12 for y in (ay, by)):
            found.append(f"{skey}: it reaches outside the domain x in [{x0}, {x1}], y in [{y0}, {y1}]")
            continue
        if not all(on_grid(v, o, h) for v, o in ((ax, x0), (bx, x0), (ay, y0), (by, y0))):
            found.append(f"{skey}: its ends must lie on mesh nodes (every {h:g} mm from ({x0:g}, {y0:g})); it is not snapped")
            continue
        n = int(round(max(abs(bx - ax), abs(by - ay)) / h))
        t = (np.arange(n) + 0.5) / n
        mx, my = ax + t * (bx - ax), ay + t * (by - ay)   # the midpoints of its element edges
        dx, dy = (0.0, 0.5 * h) if abs(ay - by) <= 1e-12 else (0.5 * h, 0.0)
        def solid(x, y):
            inside = (x > x0) & (x < x1) & (y > y0) & (y < y1)
            return inside & ~geometry.in_cutout(scene, x, y)

        if not (solid(mx - dx, my - dy) ^ solid(mx + dx, my + dy)).all():
            found.append(f"{skey}: it must lie on the solid's boundary (an edge of a cut-out or of the domain), "
                         "with material on one side only all along")
    return found


def _solid_nodes_on(scene: dict, condition: Condition, h: float) -> np.ndarray:
    """The mesh nodes (n, 2) on a condition's part, or its point, that belong to a solid cell."""

    (ax, ay), (bx, by) = condition.start, condition.end
    n = int(round(max(abs(bx - ax), abs(by - ay)) / h))
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = ax + t * (bx - ax), ay + t * (by - ay)
    keep = geometry.node_in_solid(scene, x, y, h)
    return np.column_stack([x[keep], y[keep]])


def rigid_body_motions_left(held: list[Condition]) -> list[str]:
    """The rigid-body motions of the plane that the prescribed components do not stop.

    A rigid motion is u = (a - c y, b + c x); a prescribed x component at (px, py) demands
    a - c py = 0, a y component b + c px = 0. Along a straight part these are linear in the
    position, so its two ends stand for it. The motions left are the null space of those rows."""
    rows = []
    for c in held:
        for px, py in (c.start, c.end):
            rows.append([1.0, 0.0, -py] if c.component == 0 else [0.0, 1.0, px])
    if not rows:
        return ["x translation", "y translation", "rotation"]
    matrix = np.asarray(rows)
    _, singular, vt = np.linalg.svd(matrix)
    scale = max(1.0, np.abs(matrix).max())
    rank = int((singular > 1e-10 * scale).sum())
    names = []
    for mode in vt[rank:]:
        a, b, c = mode / np.abs(mode).max()
        if abs(c) > 1e-8:
            names.append("a rotation")
        elif abs(a) > 1e-8 and abs(b) > 1e-8:
            names.append("a translation")
        else:
            names.append("x translation" if abs(a) > 1e-8 else "y translation")
    return names


def anchor_points(scene: dict) -> list[tuple[float, float]]:
    """The points a mesh must have as nodes for the supports to be those of the config: the ends
    of parts of edges and the point supports (a whole edge's ends are the domain's corners)."""
    found = []
    for edge, spec in scene["boundary"].items():
        if edge == "points":
            found += [(float(p["at"][0]), float(p["at"][1])) for p in spec]
        elif edge == "segments":
            found += [tuple(map(float, s["from"])) for s in spec] + [tuple(map(float, s["to"])) for s in spec]
        elif isinstance(spec, list):
            for part in spec:
                start, end = _edge_segment(edge, scene["domain"], part["range"])
                found += [start, end]
    return found


def anchor_cells(scene: dict, origin, h_fine: float, shape: tuple[int, int]) -> np.ndarray:
    """Fine cells (rows = y, columns = x, ``shape``) that touch an anchor point: refined, they make
    the point a node, and not a hanging one, of a quadtree mesh (and refine where a support or a
    load concentrates the stress)."""
    mask = np.zeros(shape, dtype=bool)
    ny, nx = shape
    for px, py in anchor_points(scene):
        i, j = (px - origin[0]) / h_fine, (py - origin[1]) / h_fine
        columns = sorted({int(np.floor(i + 1e-9)), int(np.ceil(i - 1e-9)) - 1})
        rows = sorted({int(np.floor(j + 1e-9)), int(np.ceil(j - 1e-9)) - 1})
        for r in rows:
            for c in columns:
                if 0 <= r < ny and 0 <= c < nx:
                    mask[r, c] = True
    return mask
