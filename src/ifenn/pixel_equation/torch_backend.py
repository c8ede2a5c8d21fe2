"""The pixel equation in torch: the batched residual and physics loss the network trains on, and
one image's residual and box solves on a device (:class:`TorchPixelEquation`, the GPU's verified
step), with the Gaussian smoothing and the failing pixels' bounding box there.

The same equation as :mod:`ifenn.pixel_equation.numpy_backend`, from the same coefficients
(:class:`ifenn.pixel_equation.definition.PixelOperator`) and stencil. Conventions: a pixel map is
(ny_px, nx_px), row 0 the bottom of the domain; batches are (n_maps, 1, ny_px, nx_px). Units: N
and mm; H in N/mm^2, Gc in N/mm, lc and h_px in mm.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
import torch.nn.functional as F

from ifenn.errors import SolverDivergedError
from ifenn.models import phase_field_model
from ifenn.pixel_equation.definition import PixelOperator, edges_of, level_shapes
from ifenn.pixel_equation.torch_multigrid import BoxCG, DeviceMultigrid, Level, LinkSum, ghosted
from ifenn.pixels import LAPLACIAN_CENTRE_WEIGHT, LAPLACIAN_K9_STAR, Box, SlitCuts, grow_box

#: Padding modes understood by the network and the Laplacian. "zeros": values beyond the
#: image are 0; "replicate": the edge value is repeated (zero flux for the Laplacian).
PADDING_MODES = ("zeros", "replicate", "reflect", "circular")


def pad(field: torch.Tensor, radius: int, padding: str) -> torch.Tensor:
    """Pad the last two dimensions of ``field`` (n, c, ny, nx) by ``radius`` pixels."""
    if padding not in PADDING_MODES:
        raise ValueError(f"padding must be one of {PADDING_MODES}, got {padding!r}")
    if radius == 0:
        return field
    mode = "constant" if padding == "zeros" else padding
    return F.pad(field, (radius, radius, radius, radius), mode=mode)


def laplacian_9pt(phi: torch.Tensor, h_px: float, padding: str = "zeros", cuts=None) -> torch.Tensor:
    """Isotropic 9-point Laplacian (K9*(phi) - 3 phi) / h_px^2.

    phi : (n, 1, ny, nx) tensor; h_px : pixel spacing in mm; padding : "zeros" (phi = 0
    beyond the image, the released script) or "replicate" (zero flux); cuts : the stencil links
    the scene's slits cut (:class:`ifenn.pixels.SlitCuts` of this image's shape), left out.
    Returns (n, 1, ny, nx), units 1/mm^2.
    """
    stencil = torch.as_tensor(LAPLACIAN_K9_STAR, dtype=phi.dtype, device=phi.device).reshape(1, 1, 3, 3)
    neighbours = F.conv2d(pad(phi, 1, padding), stencil) + LAPLACIAN_CENTRE_WEIGHT * phi
    if cuts:
        # cuts of one image apply to every image of the batch; stacked cuts (n, ny, nx) to each its own
        batch = len(cuts.shape) == 3
        if tuple(phi.shape[-2:]) != tuple(cuts.shape[-2:]) or (batch and phi.shape[0] * phi.shape[1] != cuts.shape[0]):
            raise ValueError(f"slit cuts of a {cuts.shape} image on a {tuple(phi.shape)} one")
        flat = phi.reshape(-1) if batch else phi.reshape(*phi.shape[:-2], -1)
        rows, cols = torch.as_tensor(cuts.rows, device=phi.device), torch.as_tensor(cuts.cols, device=phi.device)
        weights = torch.as_tensor(cuts.weights, dtype=phi.dtype, device=phi.device)
        flux = torch.zeros_like(flat).index_add_(-1, rows, weights * (flat[..., cols] - flat[..., rows]))
        neighbours = neighbours - flux.reshape(phi.shape)
    return neighbours / h_px**2


def residual(
    phi: torch.Tensor,
    history: torch.Tensor,
    Gc: float,
    lc: float,
    h_px: float,
    padding: str = "zeros",
    cuts=None,
    model=None,
) -> torch.Tensor:
    """Pixel residual R = (Gc/lc) phi - Gc lc Lap(phi) - 2 (1 - phi) H, N/mm^2 (the terms of the
    phase-field ``model``, :mod:`ifenn.models`; default the paper's).

    phi, history : (n, 1, ny, nx) tensors (history in N/mm^2, already capped if wanted);
    cuts : the slits' cut stencil links (:func:`laplacian_9pt`).
    """
    model = model if model is not None else phase_field_model()
    return (model.pixel_reaction0(Gc, lc) * phi - model.pixel_diffusion(Gc, lc) * laplacian_9pt(phi, h_px, padding, cuts)
            - model.pixel_driving(phi, history))


def physics_loss(
    phi: torch.Tensor,
    history: torch.Tensor,
    Gc: float,
    lc: float,
    h_px: float,
    padding: str = "zeros",
    pixel_weight: torch.Tensor | None = None,
    cuts=None,
    model=None,
) -> torch.Tensor:
    """Loss L = ||R||_2 over all pixels of all images (the paper's eq. for L), N/mm^2.

    ``pixel_weight`` (same shape as phi, optional) multiplies R^2 pixel by pixel before the
    sum; training on crops uses it to mask the crop margins and to weight samples. ``cuts``: the
    slits' cut stencil links (:func:`laplacian_9pt`; stacked ones for a batch of crops). ``model``:
    the phase-field model whose equation R is (:func:`residual`; default the paper's).
    """
    r = residual(phi, history, Gc, lc, h_px, padding, cuts, model)
    squared = r**2 if pixel_weight is None else pixel_weight * r**2
    return torch.sqrt(squared.sum())


class TorchPixelEquation(PixelOperator):
    """The pixel equation of one image in torch on ``device`` (float64): the whole image's
    residual and box solves (:class:`ifenn.pixel_equation.numpy_backend.PixelEquation`'s, same
    operator, same cut links)."""

    def __init__(self, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts: SlitCuts | None = None,
                 device="cpu", model=None):
        super().__init__(Gc, lc, h_px, padding, cuts, model)
        self.device = torch.device(device)
        self._stencil = torch.as_tensor(LAPLACIAN_K9_STAR, dtype=torch.float64, device=self.device).reshape(1, 1, 3, 3)
        self._cuts_t = None
        if self.cuts is not None:
            self._cuts_t = (torch.as_tensor(self.cuts.rows, device=self.device), torch.as_tensor(self.cuts.cols, device=self.device),
                            torch.as_tensor(self.cuts.weights, dtype=torch.float64, device=self.device),
                            LinkSum(self.cuts.rows, self.device))
        self._grids: dict = {}   # box -> its CG (finest level in float64, multigrid, buffers, graph)

    def residual(self, phi: torch.Tensor, history: torch.Tensor, normalised: bool = True) -> torch.Tensor:
        """R = a phi - D (K9*(phi) - 3 phi) - 2 H on the whole image (the slits' links cut), or R / a."""
        rep = self.padding == "replicate"
        neighbours = F.conv2d(ghosted(phi, (rep,) * 4)[None, None], self._stencil)[0, 0]
        a = self.reaction(history)
        residual = a * phi - self.diffusion * (neighbours - 3.0 * phi) - 2.0 * history
        if self._cuts_t is not None:
            rows, cols, weights, links = self._cuts_t
            flat = phi.reshape(-1)
            flux = links.add_to(torch.zeros_like(flat), weights * (flat[cols] - flat[rows]))
            residual = residual + self.diffusion * flux.reshape(phi.shape)
        return residual / a if normalised else residual

    def _grid(self, box: Box, image_shape) -> BoxCG:
        key = (box[0].start, box[0].stop, box[1].start, box[1].stop)
        if key not in self._grids:
            replicate = edges_of(box, image_shape) if self.padding == "replicate" else (False,) * 4
            shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
            links = [None]
            if self.cuts is not None:
                links = [self.cuts.in_box(box)]
                links += [self.cuts.coarse_links(box, k, coarse) for k, coarse in enumerate(level_shapes(shape)[1:], start=1)]
            if len(self._grids) > 16:
                self._grids.clear()
            self._grids[key] = BoxCG(Level(shape, replicate, links[0], torch.float64, self.device),
                                      DeviceMultigrid(shape, replicate, links, self.device))
        return self._grids[key]

    def solve_box(self, phi: torch.Tensor, history: torch.Tensor, box: Box, target: float, maxiter: int = 1000) -> tuple[float, int]:
        """Solve the pixel equation on ``box`` in place in ``phi`` (the values around it fixed) to
        max |r| <= ``target`` inside it: CG in float64 preconditioned with one float32 V-cycle.
        Returns (max |r| reached, iterations); raises if ``maxiter`` iterations do not get there."""
        cg = self._grid(box, phi.shape)
        a = self.reaction(history[box])
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


def bounding_box(mask: torch.Tensor, grow: int) -> Box | None:
    """The box of the True pixels grown by ``grow`` (None if there are none): found on the device
    and brought to the host in one transfer (nonzero and five reads would sync six times)."""
    rows, cols = mask.any(dim=1), mask.any(dim=0)

    def first_last(v):
        return torch.argmax(v.to(torch.uint8)), v.numel() - 1 - torch.argmax(torch.flip(v, (0,)).to(torch.uint8))

    found, r0, r1, c0, c1 = torch.stack([rows.any().long(), *first_last(rows), *first_last(cols)]).tolist()
    if not found:
        return None
    return grow_box((slice(r0, r1 + 1), slice(c0, c1 + 1)), grow, tuple(mask.shape))
