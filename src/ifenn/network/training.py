"""Training and scoring of the PICNN.

The loss is the pixel residual of the phase-field equation (``ifenn.pixel_equation.torch_backend.residual``); no
labels are used. Three named presets (``PRESETS``):

* ``"released"``: the authors' released script: Adam, lr 1e-3, 5,000 epochs of full images,
  zero padding (network and Laplacian), unscaled input, the plain residual norm.
* ``"text"``: the paper's text: lr 1e-4, 10,000 epochs, otherwise as "released".
* ``"tiles"`` (the project default): the paper's argument that only the fracture
  process zone matters, made cheap, plus three changes that make the far field learnable:

  - Tiles. The network is local (receptive radius 8 pixels, 9 with the Laplacian), so the
    residual at a pixel depends only on the 19x19 history patch around it. Each map is cut
    into tiles of ``tile_size`` pixels, each evaluated on a crop with 9 pixels of context,
    which reproduces the full-image residual on the tile exactly (tested). A tile is in
    the process zone if H >= Gc/lc within 2 lc of it. Each step draws a few process-zone
    tiles and a few far-field tiles, each pixel weighted by (tiles of its kind / tiles
    drawn), so the step's loss is an unbiased estimate of the full-image loss.
  - Input scaling "log": x = log((H + 0.01) / (Gc/(2 lc) + 0.01)). The unscaled input maps
    H ~ 0 (the shielded region behind the notch, 10% of the snt1 pixels) to phi ~ 1/2 and
    cannot resolve the far field (H ~ 1-10) next to the crack (H ~ 1e4).
  - Residual scaling R / (Gc/lc + 2H)^(1/2): the plain residual weighs a phi error on the
    crack (dR/dphi ~ 2H ~ 1e5) a thousand times more than in the far field
    (dR/dphi ~ Gc/lc + 2H ~ 100); the far field, most of the pixels, is then never fitted.
    Dividing by the full reaction coefficient (exponent 1) balances the two but lets the
    crack core drop (max phi ~0.90 instead of ~0.97); the square root is the compromise.
  - Replicate (zero-flux) padding in the network and the Laplacian: the FEM's boundary
    condition. The exact pixel solution then differs from the FEM phi by ~1e-4 (mean
    absolute), against ~5e-3 with zero padding (phi = 0 beyond the image).

Settings (``DEFAULT_SETTINGS`` holds the defaults; a preset overrides some; the caller's
dict overrides both):

lr : Adam learning rate at the start (1e-3).
lr_final : learning rate at the last epoch, cosine decay from lr; None = constant (None).
epochs : optimiser steps, on tile batches ("tiles") or full images ("full") (5000).
sampling : "full" (every step sees every pixel of every map) or "tiles": tiles around the process zone and a few far-field ones ("full").
padding : padding of the network's convolutions ("zeros", as the released script).
laplacian_padding : padding of the Laplacian in the loss: "zeros" (released script, phi = 0
    beyond the image) or "replicate" (zero flux, as the FEM) ("zeros").
input_scaling, input_reference, input_centre : ``ifenn.network.picnn.InputScaling`` kind ("none"),
    reference (1.0 N/mm^2) and centre (N/mm^2; None = Gc / (2 lc)).
history_cap : H_cap, N/mm^2; the loss uses the capped history too (the config's ifenn.history_cap).
channels, kernel_size : the architecture ((1, 24, 24, 24, 1), 5).
optimiser : "adam", the only one; a key so that the config names it ("adam").
residual_scaling : "none" (the paper: R in N/mm^2) or "reaction" (R / (Gc/lc + 2H)^p, an
    equivalent form of the same equation, same exact solution) ("none").
residual_scaling_exponent : p of "reaction" (1.0).
residual_scaling_warmup : epochs at the start that use residual_scaling "none"; Adam is
    restarted when the scaling switches (0).
tile_size : interior size of a tile, pixels ("tiles" only) (46).
process_zone_history : a tile is in the process zone if H >= this (N/mm^2) within
    ``process_zone_margin`` of it; None = Gc/lc (None).
process_zone_margin : mm; None = 2 lc (None).
process_zone_tiles : process-zone tiles drawn per step; None = all, every step (None).
far_field_tiles : far-field tiles drawn per step, over all maps (4).
tile_weighting : "count" (a drawn pixel stands for n_kind / n_drawn pixels of its kind, so
    the loss estimates the full-image loss) or "unit" (weight 1) ("count").
full_image_epochs : full-image epochs after the tile epochs, at lr_final (0).
dtype : "float32" or "float64" ("float32").
log_every : epochs between progress-bar updates (10).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch

from ifenn.io import progress_bar
from ifenn.network.picnn import PICNN, InputScaling
from ifenn.network.settings import (  # noqa: F401 (re-exported)
    DEFAULT_HISTORY_CAP,
    DEFAULT_SETTINGS,
    PRESETS,
    SAMPLINGS,
    resolve_settings,
)
from ifenn.pixel_equation.torch_backend import residual
from ifenn.pixels import SlitCuts


# ---------------------------------------------------------------------------------------
# Tiles of the process zone
# ---------------------------------------------------------------------------------------
@dataclass
class TileBatch:
    """Crops of the history maps and the pixel weights of their loss.

    history : (n_tiles, 1, crop, crop) capped history, N/mm^2.
    weight : (n_tiles, 1, crop, crop) 1 on the tile interior, 0 on the crop margin.
    """

    history: torch.Tensor
    weight: torch.Tensor
    #: (map, row, column) of each crop's first pixel in its map
    origins: np.ndarray | None = None


def _tile_windows(n: int, tile: int, crop: int) -> list[tuple[int, int, int]]:
    """Along one axis of length n: (crop_start, tile_start, tile_stop) of every tile.

    Crops have a common length ``crop`` (clipped into the image), so that they batch; a
    tile at the image edge uses the true boundary, which the crop then shares.
    """
    windows = []
    for start in range(0, n, tile):
        stop = min(start + tile, n)
        margin = (crop - tile) // 2
        crop_start = int(np.clip(start - margin, 0, max(n - crop, 0)))
        windows.append((crop_start, start, stop))
    return windows


def make_tiles(
    history_maps: np.ndarray,
    tile_size: int,
    context: int,
    process_zone_history: float,
    process_zone_margin_px: int,
) -> tuple[TileBatch, np.ndarray]:
    """Cut every map into tiles of ``tile_size`` pixels with crops of tile_size + 2 context.

    history_maps : (n_maps, ny, nx) capped history, N/mm^2.
    context : pixels of context each side (network receptive radius + 1 for the Laplacian).
    Returns (all tiles as a TileBatch, boolean array: tile is in the process zone).
    """
    n_maps, ny, nx = history_maps.shape
    crop_y, crop_x = min(tile_size + 2 * context, ny), min(tile_size + 2 * context, nx)
    hot = history_maps >= process_zone_history
    if process_zone_margin_px > 0:
        hot = _dilate(hot, process_zone_margin_px)
    crops, weights, in_zone, origins = [], [], [], []
    for m in range(n_maps):
        for cy, ty0, ty1 in _tile_windows(ny, tile_size, crop_y):
            for cx, tx0, tx1 in _tile_windows(nx, tile_size, crop_x):
                crops.append(history_maps[m, cy : cy + crop_y, cx : cx + crop_x])
                origins.append((m, cy, cx))
                weight = np.zeros((crop_y, crop_x))
                weight[ty0 - cy : ty1 - cy, tx0 - cx : tx1 - cx] = 1.0
                weights.append(weight)
                in_zone.append(bool(hot[m, ty0:ty1, tx0:tx1].any()))
    batch = TileBatch(
        history=torch.as_tensor(np.stack(crops)[:, None]),
        weight=torch.as_tensor(np.stack(weights)[:, None]),
        origins=np.array(origins),
    )
    return batch, np.array(in_zone)


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Square dilation of the last two axes of a boolean array by ``radius`` pixels."""
    import scipy.ndimage

    structure = np.ones((1,) * (mask.ndim - 2) + (2 * radius + 1, 2 * radius + 1), dtype=bool)
    return scipy.ndimage.binary_dilation(mask, structure=structure)


# ---------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------
def _loss(model, history, weight, Gc, lc, h_px, laplacian_padding, residual_scaling, exponent, cuts=None) -> torch.Tensor:
    phi = model.phase_field(history)
    r = residual(phi, history, Gc, lc, h_px, laplacian_padding, cuts)
    if residual_scaling == "reaction":
        r = r / (Gc / lc + 2.0 * history) ** exponent
    elif residual_scaling != "none":
        raise ValueError(f"unknown residual_scaling {residual_scaling!r}")
    squared = r**2 if weight is None else weight * r**2
    return torch.sqrt(squared.sum())


def _learning_rate(s: dict, epoch: int) -> float:
    """Cosine decay from lr to lr_final over the crop/full epochs (constant if lr_final None)."""
    if s["lr_final"] is None or s["epochs"] <= 1:
        return s["lr"]
    t = epoch / (s["epochs"] - 1)
    return s["lr_final"] + 0.5 * (s["lr"] - s["lr_final"]) * (1.0 + math.cos(math.pi * t))


def train_picnn(
    history_maps: list[np.ndarray],
    h_px: float,
    Gc: float,
    lc: float,
    settings: dict | None = None,
    seed: int = 0,
    threads: int = 1,
    progress: bool = True,
    monitor=None,
    monitor_every: int = 100,
    cuts=None,
    device="cpu",
) -> tuple[PICNN, pd.DataFrame]:
    """Train a PICNN on history pixel maps with the physics loss only.

    history_maps : list of (ny, nx) arrays of H in N/mm^2 (all the same shape).
    h_px : pixel spacing, mm; Gc : N/mm; lc : mm.
    settings : see the module docstring (``resolve_settings`` fills the defaults).
    seed, threads : same seed and threads -> identical weights.
    cuts : the stencil links the maps' slits cut (:class:`ifenn.pixels.SlitCuts` of the maps'
        shape): the loss is the pixel equation the verified step checks, on crops and full images.
    monitor : optional callable model -> dict of numbers, called every ``monitor_every``
        epochs and after the last; its values become extra columns of the log (NaN
        elsewhere). Its time is excluded from wall_s.
    device : where the epochs run (a torch device or a setting of :func:`ifenn.device.resolve_device`);
        the initial weights are drawn on the CPU, so a seed gives the same start on every device.
    Returns (trained model in eval mode, on the CPU, loss log with columns epoch, loss, wall_s, stage),
    where loss is the loss of that epoch's batch (crops or full images) and wall_s the
    elapsed training time in seconds.
    """
    from ifenn.device import resolve_device

    s = resolve_settings(settings)
    device = resolve_device(device)
    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    was_deterministic = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True)
    try:
        model, log = _train(history_maps, h_px, Gc, lc, s, seed, progress, monitor, monitor_every, cuts, device)
        return model.cpu(), log
    finally:
        torch.use_deterministic_algorithms(was_deterministic)


def _train(history_maps, h_px, Gc, lc, s, seed, progress, monitor, monitor_every, cuts=None, device=None):
    """train_picnn with resolved settings ``s``, inside the deterministic-algorithms guard."""
    rng = np.random.default_rng(seed)
    dtype = getattr(torch, s["dtype"])
    if s["optimiser"] != "adam":
        raise ValueError("only the Adam optimiser is implemented")

    model = PICNN(
        channels=tuple(s["channels"]),
        kernel_size=s["kernel_size"],
        padding=s["padding"],
        history_cap=s["history_cap"],
        input_scaling=InputScaling(
            s["input_scaling"],
            s["input_reference"],
            s["input_centre"] if s["input_centre"] is not None else Gc / (2.0 * lc),
        ),
    ).to(dtype)
    capped = np.minimum(np.maximum(np.stack(history_maps), 0.0), s["history_cap"])
    model.to(device)
    full_history = torch.as_tensor(capped[:, None], dtype=dtype, device=device)

    if s["sampling"] == "tiles":
        pz_history = s["process_zone_history"] if s["process_zone_history"] is not None else Gc / lc
        pz_margin = s["process_zone_margin"] if s["process_zone_margin"] is not None else 2 * lc
        tiles, in_zone = make_tiles(
            capped, s["tile_size"], model.receptive_radius + 1, pz_history, int(math.ceil(pz_margin / h_px))
        )
        zone_idx, far_idx = np.flatnonzero(in_zone), np.flatnonzero(~in_zone)
        n_far_drawn = min(s["far_field_tiles"], far_idx.size)
        n_zone_drawn = zone_idx.size if s["process_zone_tiles"] is None else min(s["process_zone_tiles"], zone_idx.size)
        zone_scale = zone_idx.size / n_zone_drawn if (n_zone_drawn and s["tile_weighting"] == "count") else 1.0
        far_scale = far_idx.size / n_far_drawn if (n_far_drawn and s["tile_weighting"] == "count") else 1.0
        tile_history, tile_weight = tiles.history.to(device, dtype), tiles.weight.to(device, dtype)
        crop_shape = tuple(tiles.history.shape[-2:])
        tile_cuts = [cuts.crop((slice(cy, cy + crop_shape[0]), slice(cx, cx + crop_shape[1]))) for _, cy, cx in tiles.origins] \
            if cuts else None
    elif s["sampling"] != "full":
        raise ValueError(f"unknown sampling {s['sampling']!r}")

    optimiser = torch.optim.Adam(model.parameters(), lr=s["lr"])
    log = []
    n_total = s["epochs"] + (s["full_image_epochs"] if s["sampling"] == "tiles" else 0)
    bar = progress_bar(total=n_total, disable=not progress, desc="PICNN training", unit="epoch")
    start = time.perf_counter()
    for epoch in range(n_total):
        crop_stage = s["sampling"] == "tiles" and epoch < s["epochs"]
        lr = _learning_rate(s, min(epoch, s["epochs"] - 1))
        for group in optimiser.param_groups:
            group["lr"] = lr
        if crop_stage:
            zone = np.sort(rng.choice(zone_idx, size=n_zone_drawn, replace=False))
            far = np.sort(rng.choice(far_idx, size=n_far_drawn, replace=False))
            index = torch.as_tensor(np.concatenate([zone, far]), device=device)
            weight = tile_weight[index].clone()
            weight[:n_zone_drawn] *= zone_scale
            weight[n_zone_drawn:] *= far_scale
            history, stage = tile_history[index], "crops"
            batch_cuts = SlitCuts.stacked([tile_cuts[i] for i in index.tolist()]) if tile_cuts else None
        else:
            history, weight, stage = full_history, None, "full"
            batch_cuts = cuts
        optimiser.zero_grad(set_to_none=True)
        scaling = "none" if epoch < s["residual_scaling_warmup"] else s["residual_scaling"]
        if epoch == s["residual_scaling_warmup"] and epoch > 0:
            # The loss changes scale by orders of magnitude: Adam's second moments would
            # otherwise shrink the steps for ~1/(1 - beta2) epochs.
            optimiser = torch.optim.Adam(model.parameters(), lr=lr)
        loss = _loss(
            model, history, weight, Gc, lc, h_px, s["laplacian_padding"], scaling, s["residual_scaling_exponent"], batch_cuts
        )
        loss.backward()
        optimiser.step()
        row = {"epoch": epoch, "loss": loss.item(), "wall_s": time.perf_counter() - start, "stage": stage}
        if monitor is not None and (epoch % monitor_every == 0 or epoch == n_total - 1):
            paused = time.perf_counter()
            model.eval()
            row.update(monitor(model))
            model.train()
            start += time.perf_counter() - paused
        log.append(row)
        bar.update(1)
        if epoch % s["log_every"] == 0:
            bar.set_postfix(loss=f"{loss.item():.4g}", stage=stage)
    bar.close()
    model.eval()
    return model, pd.DataFrame(log)


# ---------------------------------------------------------------------------------------
# Scoring against FEM
# ---------------------------------------------------------------------------------------
#: Defaults of score_picnn: reference phi above which a pixel is scored as "crack" (any damage
#: worth scoring: 0.05, not the crack set {phi >= 0.5} of ifenn.studies.tables.metrics.CRACK_PHI) / "fully broken".
SCORE_CRACK_PHI = 0.05
BROKEN_PHI = 0.9


def score_picnn(
    model: PICNN,
    history_maps: list[np.ndarray],
    fem_phi_maps: list[np.ndarray],
    crack_phi: float = SCORE_CRACK_PHI,
    broken_phi: float = BROKEN_PHI,
    smoothing=None,
) -> list[dict]:
    """Accuracy of the PICNN phase field against reference phi maps, per increment.

    history_maps, fem_phi_maps : lists of (ny, nx) arrays (H in N/mm^2, phi in [0, 1]).
    crack_phi : pixels where the reference phi > crack_phi are "crack pixels" (0.05).
    broken_phi : pixels where the reference phi > broken_phi are "broken" (0.9).
    smoothing : optional callable phi -> phi applied to the prediction (e.g. Gaussian).
    Returns one dict per increment: mae_all, mae_crack, max_phi_broken (max predicted phi
    where the reference > broken_phi), min_phi_broken, max_abs_error, n_crack, n_broken.
    """
    scores = []
    for history, reference in zip(history_maps, fem_phi_maps, strict=True):
        predicted = model.predict(history)
        if smoothing is not None:
            predicted = smoothing(predicted)
        error = np.abs(predicted - reference)
        crack, broken = reference > crack_phi, reference > broken_phi
        scores.append(
            {
                "mae_all": float(error.mean()),
                "mae_crack": float(error[crack].mean()) if crack.any() else float("nan"),
                "max_phi_broken": float(predicted[broken].max()) if broken.any() else float("nan"),
                "min_phi_broken": float(predicted[broken].min()) if broken.any() else float("nan"),
                "max_abs_error": float(error.max()),
                "n_crack": int(crack.sum()),
                "n_broken": int(broken.sum()),
            }
        )
    return scores


# ---------------------------------------------------------------------------------------
# Synthetic stand-in for FEM history maps (tests, benchmarks, development)
# ---------------------------------------------------------------------------------------
def synthetic_history(
    n_px: int = 400,
    h_px: float = 0.0025,
    x_tip: float = -0.05,
    lc: float = 0.03,
    band_peak: float = 2.0e5,
    band_width_px: float = 1.0,
    tip_peak: float = 800.0,
    far_field: tuple[float, float, float] = (1.0, 3.0, 2.0),
    far_field_length: float = 0.3,
    history_cap: float = DEFAULT_HISTORY_CAP,
) -> np.ndarray:
    """A snt-like history map (N/mm^2), shape (n_px, n_px), square domain centred at 0.

    A crack band along y = 0 for x < x_tip: band_peak exp(-(y / (band_width_px h_px))^2);
    a tip field tip_peak / (1 + 2 r / lc)^2 (r = distance to the crack segment, mm); a far
    field a + b (y + 1/2) + c exp(-(r_tip / far_field_length)^2) with (a, b, c) = far_field
    (N/mm^2) and far_field_length in mm (r_tip = distance to the tip), i.e. a few
    N/mm^2 like the FEM far field. Capped at history_cap. Not a solution of anything: only
    a stand-in with the right magnitudes and shapes.
    """
    centres = -0.5 * n_px * h_px + h_px * (np.arange(n_px) + 0.5)
    x, y = np.meshgrid(centres, centres, indexing="xy")
    r = np.hypot(np.maximum(x - x_tip, 0.0), y)
    band = band_peak * np.exp(-((y / (band_width_px * h_px)) ** 2)) * (x < x_tip)
    tip = tip_peak / (1.0 + 2.0 * r / lc) ** 2
    a, b, c = far_field
    far = a + b * (y + 0.5) + c * np.exp(-((np.hypot(x - x_tip, y) / far_field_length) ** 2))
    return np.minimum(band + tip + far, history_cap)
