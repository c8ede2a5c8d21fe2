"""Physics-informed CNN (PICNN) for the phase field: the network, its input scaling, and its file.

Conventions:

* A pixel map is a float array of shape ``(ny_px, nx_px)``; row ``iy`` increases with y
  (row 0 is the bottom of the domain), column ``ix`` increases with x. Batches of maps have
  shape ``(n_maps, ny_px, nx_px)``; torch tensors used inside the network have shape
  ``(n_maps, 1, ny_px, nx_px)``.
* Units: N and mm. ``history`` H is in N/mm^2; the phase field ``phi`` is dimensionless in [0, 1].

The equation the network is trained on, its residual and its exact solve are the pixel
equation's (:mod:`ifenn.pixel_equation`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ifenn.io import atomic_path, reading
from ifenn.network.settings import DEFAULT_HISTORY_CAP  # H_cap, N/mm^2: the config schema's, the constructor's default
from ifenn.pixel_equation.torch_backend import PADDING_MODES, pad

#: Padding modes understood by the network and the Laplacian. "zeros": values beyond the
#: image are 0; "replicate": the edge value is repeated (zero flux for the Laplacian).

# ---------------------------------------------------------------------------------------
# Symmetric convolution
# ---------------------------------------------------------------------------------------
def symmetric_kernel_index(kernel_size: int) -> tuple[np.ndarray, int]:
    """Index map of a kernel invariant under the 8 symmetries of the square.

    Entry (i, j) of a ``kernel_size`` x ``kernel_size`` kernel depends only on the
    unordered pair (|di|, |dj|) of its offsets from the centre.

    Returns
    -------
    index : (kernel_size, kernel_size) int array, entries in [0, n_free)
    n_free : number of free values per kernel, (r + 1)(r + 2)/2 with r = kernel_size // 2
        (6 for a 5x5 kernel).
    """
    if kernel_size % 2 != 1:
        raise ValueError(f"kernel_size must be odd, got {kernel_size}")
    radius = kernel_size // 2
    pairs = [(a, b) for a in range(radius + 1) for b in range(a, radius + 1)]
    pair_index = {pair: k for k, pair in enumerate(pairs)}
    offsets = np.abs(np.arange(kernel_size) - radius)
    index = np.empty((kernel_size, kernel_size), dtype=np.int64)
    for i, di in enumerate(offsets):
        for j, dj in enumerate(offsets):
            index[i, j] = pair_index[(min(di, dj), max(di, dj))]
    return index, len(pairs)


class SymmetricConv2d(nn.Module):
    """2-D convolution without bias whose kernels are invariant under the dihedral group D4.

    Each (out, in) kernel has ``n_free`` learnable values (6 for 5x5), gathered into the
    full kernel on every forward pass, so the layer commutes with 90-degree rotations and
    mirror images of its input. "Same" padding: output size = input size.

    Parameters
    ----------
    in_ch, out_ch : numbers of input and output channels.
    kernel_size : odd kernel size (default 5).
    padding : one of ``PADDING_MODES`` (default "zeros").
    init_gain : the free values are drawn from U(-b, b), b = init_gain * sqrt(6 / (fan_in +
        fan_out)) with fan = channels * kernel_size^2 (Glorot for tanh; default 1).
    """

    def __init__(
        self,
        in_ch: int,
        out_ch: int,
        kernel_size: int = 5,
        padding: str = "zeros",
        init_gain: float = 1.0,
    ):
        super().__init__()
        if padding not in PADDING_MODES:
            raise ValueError(f"padding must be one of {PADDING_MODES}, got {padding!r}")
        index, n_free = symmetric_kernel_index(kernel_size)
        self.in_ch, self.out_ch, self.kernel_size, self.padding = in_ch, out_ch, kernel_size, padding
        self.register_buffer("kernel_index", torch.as_tensor(index.reshape(-1)), persistent=False)
        bound = init_gain * np.sqrt(6.0 / ((in_ch + out_ch) * kernel_size**2))
        self.free_weight = nn.Parameter(torch.empty(out_ch, in_ch, n_free).uniform_(-bound, bound))

    def kernel(self) -> torch.Tensor:
        """Full kernel, shape (out_ch, in_ch, kernel_size, kernel_size)."""
        k = self.kernel_size
        return self.free_weight[:, :, self.kernel_index].reshape(self.out_ch, self.in_ch, k, k)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (n, in_ch, ny, nx) -> (n, out_ch, ny, nx)."""
        radius = self.kernel_size // 2
        if self.padding == "zeros":
            return F.conv2d(x, self.kernel(), padding=radius)
        return F.conv2d(pad(x, radius, self.padding), self.kernel())


# ---------------------------------------------------------------------------------------
# Input scaling
# ---------------------------------------------------------------------------------------
INPUT_SCALING_KINDS = ("none", "linear", "log1p", "log")


@dataclasses.dataclass(frozen=True)
class InputScaling:
    """Map from the capped history H_c = clamp(H, 0, H_cap) (N/mm^2) to the network input x.

    kind
        "none": x = H_c (the authors' script);
        "linear": x = H_c / reference;
        "log1p": x = log(1 + H_c / reference);
        "log": x = log((H_c + reference) / (centre + reference)).
    reference
        N/mm^2. For "log" the floor below which histories look alike (a small fraction of
        the far-field history, e.g. 0.01 N/mm^2, so that the shielded region behind a
        notch, H ~ 1e-5 to 1e-2, is told apart from the far field, H ~ 1 to 10).
    centre
        N/mm^2, "log" only: the history mapped to x = 0. With no biases x = 0 gives
        phi = 1/2 exactly, so the natural centre is Gc / (2 lc), the history at which the
        local solution 2H / (Gc/lc + 2H) is 1/2; H = 0 then maps to a large negative x
        (phi near 0) instead of phi = 1/2 as with the other kinds.
    """

    kind: str = "none"
    reference: float = 1.0
    centre: float = 0.0

    def __post_init__(self):
        if self.kind not in INPUT_SCALING_KINDS:
            raise ValueError(f"input scaling kind must be one of {INPUT_SCALING_KINDS}")
        if self.reference <= 0 or self.centre < 0:
            raise ValueError("input scaling reference must be positive and centre non-negative")

    def __call__(self, capped_history: torch.Tensor) -> torch.Tensor:
        if self.kind == "none":
            return capped_history
        if self.kind == "linear":
            return capped_history / self.reference
        if self.kind == "log1p":
            return torch.log1p(capped_history / self.reference)
        return torch.log((capped_history + self.reference) / (self.centre + self.reference))


# ---------------------------------------------------------------------------------------
# The network
# ---------------------------------------------------------------------------------------
DEFAULT_CHANNELS = (1, 24, 24, 24, 1)


class PICNN(nn.Module):
    """Fully convolutional PICNN: history pixels H -> phase-field pixels phi.

    Layers: SymmetricConv2d for each consecutive channel pair, tanh after every layer but
    the last, sigmoid after the last. No bias, normalisation, pooling or dense layer, so
    any image size works and the whole map is equivariant to the 8 symmetries of the
    square. Receptive field: 1 + (n_layers)(kernel_size - 1) pixels (17 for the default).

    The input pre-processing (cap at ``history_cap``, then ``input_scaling``) lives in the
    model and is applied by :meth:`phase_field`, the one path used by training and, via
    :meth:`predict`, by inference.

    Parameters
    ----------
    channels : channel counts, input first (default (1, 24, 24, 24, 1)).
    kernel_size : odd kernel size (default 5).
    padding : padding mode of every convolution (default "zeros").
    history_cap : H_cap in N/mm^2 (default 5e4).
    input_scaling : :class:`InputScaling` (default: unscaled, as in the authors' script).
    init_gain : see :class:`SymmetricConv2d`.
    """

    def __init__(
        self,
        channels: tuple[int, ...] = DEFAULT_CHANNELS,
        kernel_size: int = 5,
        padding: str = "zeros",
        history_cap: float = DEFAULT_HISTORY_CAP,
        input_scaling: InputScaling | None = None,
        init_gain: float = 1.0,
    ):
        super().__init__()
        if channels[0] != 1 or channels[-1] != 1:
            raise ValueError("the PICNN maps one channel (H) to one channel (phi)")
        self.channels = tuple(int(c) for c in channels)
        self.kernel_size = int(kernel_size)
        self.padding = padding
        self.history_cap = float(history_cap)
        self.input_scaling = input_scaling if input_scaling is not None else InputScaling()
        self.layers = nn.ModuleList(
            SymmetricConv2d(c_in, c_out, kernel_size, padding, init_gain)
            for c_in, c_out in zip(self.channels[:-1], self.channels[1:], strict=True)
        )

    @property
    def receptive_radius(self) -> int:
        """Pixels of context on each side that an output pixel depends on (8 for default)."""
        return len(self.layers) * (self.kernel_size // 2)

    def forward(self, network_input: torch.Tensor) -> torch.Tensor:
        """Scaled input x (n, 1, ny, nx) -> phi (n, 1, ny, nx)."""
        x = network_input
        for layer in self.layers[:-1]:
            x = torch.tanh(layer(x))
        return torch.sigmoid(self.layers[-1](x))

    def network_input(self, history: torch.Tensor) -> torch.Tensor:
        """History H (N/mm^2, any shape) -> network input: scaling of clamp(H, 0, H_cap)."""
        return self.input_scaling(torch.clamp(history, 0.0, self.history_cap))

    def phase_field(self, history: torch.Tensor) -> torch.Tensor:
        """History pixels H (n, 1, ny, nx), N/mm^2 -> phi (n, 1, ny, nx); differentiable."""
        return self(self.network_input(history))

    @torch.no_grad()
    def predict(self, history_pixels: np.ndarray) -> np.ndarray:
        """Inference: H pixel map(s) (ny, nx) or (n, ny, nx), N/mm^2 -> phi, same shape, float64."""
        history_pixels = np.asarray(history_pixels)
        batch = torch.as_tensor(history_pixels, dtype=self._dtype(), device=self.device).reshape(
            -1, 1, *history_pixels.shape[-2:]
        )
        phi = self.phase_field(batch)
        return phi.reshape(history_pixels.shape).double().cpu().numpy()

    def _dtype(self) -> torch.dtype:
        return self.layers[0].free_weight.dtype

    @property
    def device(self) -> torch.device:
        """Where the weights live (:mod:`ifenn.device`); :meth:`predict` takes and returns numpy
        arrays on the CPU and moves them to and from it."""
        return self.layers[0].free_weight.device

    def n_free_parameters(self) -> int:
        """Number of trainable values (6 per 5x5 kernel)."""
        return sum(p.numel() for p in self.parameters() if p.requires_grad)


# ---------------------------------------------------------------------------------------
# Save / load
# ---------------------------------------------------------------------------------------
def save_picnn(
    model: PICNN,
    path: str | Path,
    h_px: float,
    Gc: float,
    lc: float,
    config_hash: str,
    extra: dict | None = None,
) -> None:
    """Write the model and everything needed to rebuild and use it to one torch file.

    Written to a temporary name, then renamed, so a half-written file never looks finished.
    ``extra`` (optional, JSON-like) is stored as is, e.g. the training settings.
    """
    path = Path(path)
    payload = {
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "channels": model.channels,
        "kernel_size": model.kernel_size,
        "padding": model.padding,
        "history_cap": model.history_cap,
        "input_scaling": dataclasses.asdict(model.input_scaling),
        "h_px": float(h_px),
        "Gc": float(Gc),
        "lc": float(lc),
        "config_hash": str(config_hash),
        "extra": extra or {},
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_picnn(path: str | Path, device="cpu", history_cap: float | None = None) -> tuple[PICNN, dict]:
    """Read a file written by :func:`save_picnn` (saved from the CPU, whatever trained it).

    ``history_cap``: the cap the run puts on the network's input (N/mm^2, in the network's own
    units), which the model then applies; None keeps the cap it was trained with (the metadata's
    ``history_cap`` stays that one). The run's spec is the cap's one owner: a run that loads the
    network for inference passes its own.

    Returns (model in eval mode on ``device``, metadata dict with h_px, Gc, lc, config_hash, extra, ...).
    """
    with reading(path, "trained PICNN (torch file of ifenn.network.picnn.save_picnn)"):
        payload = torch.load(Path(path), map_location="cpu", weights_only=True)
    model = PICNN(
        channels=tuple(payload["channels"]),
        kernel_size=payload["kernel_size"],
        padding=payload["padding"],
        history_cap=payload["history_cap"] if history_cap is None else history_cap,
        input_scaling=InputScaling(**payload["input_scaling"]),
    )
    state = payload["state_dict"]
    model.to(dtype=state["layers.0.free_weight"].dtype)
    model.load_state_dict(state)
    model.to(device)
    model.eval()
    metadata = {k: v for k, v in payload.items() if k != "state_dict"}
    return model, metadata
