"""Gauss point <-> pixel maps.

An nx x ny element mesh gives a (2 ny) x (2 nx) image with pixel size h_px = h / 2; each
Gauss point maps to the pixel that contains it (floor of coordinate over h_px). Images are
indexed [iy, ix]: row 0 is the bottom of the domain (y increasing with the row index).
"""

from __future__ import annotations

from dataclasses import dataclass

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

    def image_from(self, index: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Scatter values at flat pixel indices into an image; every pixel must be hit once."""
        image = np.full(self.nx_px * self.ny_px, np.nan)
        image[index] = values
        if len(index) != image.size or np.isnan(image).any():
            raise ValueError(f"Gauss points do not cover the {self.shape} pixel grid one-to-one")
        return image.reshape(self.shape)

    def attrs(self) -> dict:
        return {"x0": self.x0, "y0": self.y0, "h_px": self.h_px, "nx_px": self.nx_px, "ny_px": self.ny_px}


# Boxes on pixel images: (row slice, column slice) with non-negative start and stop.
Box = tuple[slice, slice]


def grow_box(box: Box, by: int, shape: tuple[int, int]) -> Box:
    """``box`` grown by ``by`` pixels on every side, clipped to an image of ``shape``."""
    return tuple(slice(max(side.start - by, 0), min(side.stop + by, n)) for side, n in zip(box, shape, strict=True))


def box_within(box: Box, crop: Box) -> Box:
    """``box`` in the coordinates of the crop ``crop`` (which holds it)."""
    return tuple(slice(side.start - c.start, side.stop - c.start) for side, c in zip(box, crop, strict=True))


def box_area(box: Box) -> int:
    return (box[0].stop - box[0].start) * (box[1].stop - box[1].start)
