"""The pixel equation's one definition: its coefficients, its stencil and its padding, read by
both backends (:mod:`~ifenn.pixel_equation.numpy_backend`, :mod:`~ifenn.pixel_equation.torch_backend`).

At pixel i, for the history H (N/mm^2) of the pixel's Gauss point:

    R_i(phi) = a_i phi_i - D (K9*(phi)_i - 3 phi_i) - 2 H_i,
    a_i = Gc/lc + 2 H_i (the reaction, N/mm^2),   D = Gc lc / h_px^2 (the diffusion, N/mm^2),

with K9* the isotropic 9-point stencil (:data:`ifenn.pixels.LAPLACIAN_K9_STAR`), the stencil
links a slit cuts left out (:class:`ifenn.pixels.SlitCuts`), and the image edge read by its
padding: "replicate" (zero flux, as the FEM's natural boundary) or "zeros" (phi = 0 beyond the
image, the published training script's).
"""

from __future__ import annotations

from ifenn.models import phase_field_model
from ifenn.pixels import SlitCuts

#: paddings of the pixel equation's image edge (the network's convolutions know more: torch_backend.PADDING_MODES)
EQUATION_PADDINGS = ("replicate", "zeros")


class PixelOperator:
    """The coefficients of the pixel equation of one image (module doc): ``reaction0`` = Gc/lc,
    ``diffusion`` D = Gc lc / h_px^2 (both N/mm^2), as the phase-field ``model`` gives them
    (:mod:`ifenn.models`; default the paper's), the padding and the slits' cut links (``cuts``:
    None, no slit). Each backend's equation is one of these."""

    def __init__(self, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts: SlitCuts | None = None,
                 model=None):
        if padding not in EQUATION_PADDINGS:
            raise ValueError(f"pixel equation padding must be 'replicate' or 'zeros', got {padding!r}")
        self.Gc, self.lc, self.h_px, self.padding = Gc, lc, h_px, padding
        self.cuts = cuts if cuts else None
        self.model = model if model is not None else phase_field_model()
        self.diffusion = self.model.pixel_diffusion(Gc, lc) / h_px**2
        self.reaction0 = self.model.pixel_reaction0(Gc, lc)

    def reaction(self, history):
        """a = Gc/lc + 2 H (numpy or torch, the shape of ``history``)."""
        return self.reaction0 + 2.0 * history

    def local_solution(self, history):
        """The solution without diffusion, 2 H / (Gc/lc + 2 H): the start where nothing better is known."""
        return 2.0 * history / self.reaction(history)


def edges_of(box, shape: tuple[int, int]) -> tuple[bool, bool, bool, bool]:
    """Which image edges ``box`` meets: (bottom, top, left, right)."""
    ny, nx = shape
    return (box[0].start == 0, box[0].stop == ny, box[1].start == 0, box[1].stop == nx)


def level_shapes(shape: tuple[int, int], max_levels: int = 16) -> list[tuple[int, int]]:
    """The multigrid levels of a box of ``shape`` (finest first): halved, rounding up, while both
    sides exceed 4 cells, at most ``max_levels`` (the compiled V-cycle's and the torch one's)."""
    shapes = [tuple(shape)]
    while shapes[-1][0] > 4 and shapes[-1][1] > 4 and len(shapes) < max_levels:
        shapes.append(((shapes[-1][0] + 1) // 2, (shapes[-1][1] + 1) // 2))
    return shapes

