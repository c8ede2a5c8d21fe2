"""What every figure shares: the atomic save, a field's extent and coordinates, a zoom window."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ifenn.io import atomic_path  # noqa: E402


def save(fig, path) -> None:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    plt.close(fig)


def gauss_point_coordinates(data: dict) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (mm) of the Gauss point behind each pixel: in element (i, j) of size
    h = 2 h_px the 2x2 points sit at (i + 1/2 -+ 1/(2 sqrt 3)) h, the lower one in the even pixel."""
    h = 2.0 * float(data["h_px"])
    offset = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
    x = float(data["x0"]) + (np.arange(int(data["nx_px"])) // 2 + offset[np.arange(int(data["nx_px"])) % 2]) * h
    y = float(data["y0"]) + (np.arange(int(data["ny_px"])) // 2 + offset[np.arange(int(data["ny_px"])) % 2]) * h
    return np.meshgrid(x, y)


def extent(data: dict) -> list[float]:
    x0, y0, h = float(data["x0"]), float(data["y0"]), float(data["h_px"])
    return [x0, x0 + int(data["nx_px"]) * h, y0, y0 + int(data["ny_px"]) * h]


def window(attrs: dict, zoom: dict | None):
    """Row/column slices and extent (mm) of a zoom window {x: [a, b], y: [c, d]} of a pixel map."""
    x0, y0, h = float(attrs["x0"]), float(attrs["y0"]), float(attrs["h_px"])
    nx, ny = int(attrs["nx_px"]), int(attrs["ny_px"])
    if not zoom:
        return slice(0, ny), slice(0, nx), [x0, x0 + nx * h, y0, y0 + ny * h]
    c0, c1 = (max(int(np.floor((v - x0) / h)), 0) for v in (zoom["x"][0], zoom["x"][1]))
    r0, r1 = (max(int(np.floor((v - y0) / h)), 0) for v in (zoom["y"][0], zoom["y"][1]))
    return slice(r0, r1), slice(c0, c1), [x0 + c0 * h, x0 + c1 * h, y0 + r0 * h, y0 + r1 * h]
