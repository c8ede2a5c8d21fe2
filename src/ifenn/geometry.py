"""The solid of a scene: its rectangular domain minus its rectangular cut-outs.

A scene's ``cutouts`` lists rectangles ``{x: [a, b], y: [c, d]}`` (mm) removed from the domain
(the L-panel's missing quadrant). Their edges lie on mesh lines (:func:`cutout_problems` refuses
one that does not; nothing is snapped), so a mesh cell, a Gauss point and a pixel each lie wholly
in the solid or wholly in a cut-out. The uniform mesh keeps the solid cells
(``ifenn.fem.mesh``), and every pixel operator cuts the stencil links between a solid pixel and
a removed one, as it cuts a slit (``ifenn.pixels.SlitCuts``).
"""

from __future__ import annotations

import numpy as np


def on_grid(value: float, origin: float, h: float) -> bool:
    """Whether ``value`` lies on a mesh line of spacing ``h`` from ``origin`` (to round-off).
    Geometry between mesh lines is refused, never snapped (a slit only with ``snap: true``)."""
    steps = (value - origin) / h
    return abs(steps - round(steps)) < 1e-6


def cutouts(scene: dict) -> list[tuple[float, float, float, float]]:
    """The scene's cut-outs as (x0, x1, y0, y1), mm."""
    return [(min(c["x"]), max(c["x"]), min(c["y"]), max(c["y"])) for c in scene.get("cutouts", [])]


def in_cutout(scene: dict, x, y) -> np.ndarray:
    """Whether the points (x, y) lie strictly inside a cut-out (a point on its edge is solid)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    inside = np.zeros(np.broadcast(x, y).shape, dtype=bool)
    for a, b, c, d in cutouts(scene):
        inside |= (x > a) & (x < b) & (y > c) & (y < d)
    return inside


def solid_pixels(scene: dict, grid) -> np.ndarray:
    """(ny_px, nx_px) mask of the pixels of ``grid`` (an ``ifenn.pixels.PixelGrid``) in the solid."""
    xs, ys = grid.pixel_centres()
    return ~in_cutout(scene, xs[None, :], ys[:, None])


def node_in_solid(scene: dict, x, y, h: float) -> np.ndarray:
    """Whether the mesh nodes at (x, y) belong to a solid cell (a cell of size ``h`` that has the
    node as a corner and lies in the domain and outside every cut-out)."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    solid = np.zeros(np.broadcast(x, y).shape, dtype=bool)
    for dx in (-0.5, 0.5):
        for dy in (-0.5, 0.5):
            cx, cy = x + dx * h, y + dy * h
            in_domain = (cx > x0) & (cx < x1) & (cy > y0) & (cy < y1)
            solid |= in_domain & ~in_cutout(scene, cx, cy)
    return solid


def cutout_problems(scene: dict, key: str) -> list[str]:
    """What is wrong with the scene's cut-outs, one message per problem naming the key."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    h = (x1 - x0) / scene["elements"][0]
    found = []
    for i, cut in enumerate(scene.get("cutouts", [])):
        ckey = f"config key '{key}.cutouts[{i}]'"
        (a, b), (c, d) = cut["x"], cut["y"]
        if not (a < b and c < d):
            found.append(f"{ckey}: need x[0] < x[1] and y[0] < y[1], got {cut}")
            continue
        if not (x0 - 1e-12 <= a and b <= x1 + 1e-12 and y0 - 1e-12 <= c and d <= y1 + 1e-12):
            found.append(f"{ckey}: {cut} reaches outside the domain x in [{x0}, {x1}], y in [{y0}, {y1}]")
            continue
        off = [v for v, origin in ((a, x0), (b, x0), (c, y0), (d, y0)) if not on_grid(v, origin, h)]
        if off:
            found.append(f"{ckey}: its edges {off} are not on mesh lines (every {h:g} mm from ({x0:g}, {y0:g})); "
                         "a cut-out is not snapped: move its edges or change the elements")
        if a <= x0 + 1e-12 and b >= x1 - 1e-12 and c <= y0 + 1e-12 and d >= y1 - 1e-12:
            found.append(f"{ckey}: it removes the whole domain")
    return found


def domain_is_valid(scene: dict) -> bool:
    """x[0] < x[1] and y[0] < y[1]: the checks of anything inside the domain need it."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    return x0 < x1 and y0 < y1


def scene_problems(scene: dict, key: str) -> list[str]:
    """What the config refuses in a scene's geometry (config key ``key``), before any mesh is built:
    an empty domain, elements that are not square (the pixel map needs square ones), notches outside
    the domain, a slit off the mesh lines or not along them, and its cut-outs' problems."""
    if not domain_is_valid(scene):
        return [f"config key '{key}.domain': need x[0] < x[1] and y[0] < y[1], got {scene['domain']}"]
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    problems = []
    hx, hy = (x1 - x0) / scene["elements"][0], (y1 - y0) / scene["elements"][1]
    if abs(hx - hy) > 1e-9 * hx:  # the test of ifenn.fem.mesh.element_size, before any mesh is built
        problems.append(f"config key '{key}.elements': {scene['elements']} on the domain {scene['domain']} gives "
                        f"{hx:g} x {hy:g} mm elements; the pixel map needs square ones (allowed: elements "
                        f"proportional to the domain's sides, {(x1 - x0) / (y1 - y0):g} : 1)")
    problems += cutout_problems(scene, key)
    for i, notch in enumerate(scene.get("notches", [])):
        problems += _notch_problems(notch, f"{key}.notches[{i}]", (x0, x1, y0, y1), hx)
    return problems


def _notch_problems(notch: dict, key: str, box: tuple[float, float, float, float], h: float) -> list[str]:
    """A notch's ends inside the domain ``box`` (x0, x1, y0, y1); a slit along a mesh line of spacing
    ``h``, on it unless it snaps."""
    x0, x1, y0, y1 = box
    tol = 1e-12 * max(x1 - x0, y1 - y0)
    problems = []
    for end in ("start", "end"):
        px, py = notch[end]
        if not (x0 - tol <= px <= x1 + tol and y0 - tol <= py <= y1 + tol):
            problems.append(f"config key '{key}.{end}': point {notch[end]} lies outside the domain "
                            f"x in [{x0}, {x1}], y in [{y0}, {y1}]")
    (sx, sy), (ex, ey) = notch["start"], notch["end"]
    if notch["kind"] == "slit" and abs(sx - ex) > tol and abs(sy - ey) > tol:
        problems.append(f"config key '{key}': a slit must be horizontal or vertical (along mesh lines), "
                        f"got {notch['start']} -> {notch['end']}; use kind 'history' for other notches")
    if abs(sx - ex) <= tol and abs(sy - ey) <= tol:
        problems.append(f"config key '{key}': start and end coincide")
    elif notch["kind"] == "slit" and not notch.get("snap", False):
        off = [c for c, o in ((sx, x0), (sy, y0), (ex, x0), (ey, y0)) if not on_grid(c, o, h)]
        if off:
            problems.append(f"config key '{key}': the slit {notch['start']} -> {notch['end']} has coordinates {off} "
                            f"between mesh lines (every {h:g} mm from ({x0:g}, {y0:g})); it is not snapped: move its "
                            f"ends, change the elements, or set '{key}.snap: true' to move it to the nearest line")
    return problems
