"""A network trained for the job it has in the verified loop: the change of phi over an
increment, from what the check already computes.

Over an increment the history grows from H_old to H, and the last verified phi_old fails the new
equation by R(phi_old; H) = -2 (H - H_old)(1 - phi_old) + (phi_old's own residual); the change that
the correction must find solves A(H) delta = -R. So the network is fed, per pixel, the normalised
residual r = R(phi_old; H) / (Gc/lc + 2H) (the check's own number, no extra cost) and phi_old (where
the crack is, which sets A's local coefficient), and answers delta; the warm start is phi_old +
delta. It is trained on the states of a verified loop (in-loop data, not the two training increments
of the paper's network) with the check's own norm: the mean square of the normalised residual of
phi_old + delta under H. Its kernels have the square's 8 symmetries, as the paper's
(:class:`ifenn.network.picnn.SymmetricConv2d`), and it is linear in r up to its tanh layers' bends.

Whatever it learns, the check certifies its answer and the correction finishes it: it can change
the cost, never the result (``tests/test_network_worth.py``).
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import nn

from ifenn.network.picnn import SymmetricConv2d
from ifenn.pixel_equation.torch_backend import residual


class ChangeNet(nn.Module):
    """(r, phi_old) images (n, 2, ny, nx) -> delta (n, 1, ny, nx); ``channels`` from the 2 inputs to the 1 output."""

    def __init__(self, channels=(2, 8, 8, 1), kernel_size: int = 5, padding: str = "replicate"):
        super().__init__()
        if channels[0] != 2 or channels[-1] != 1:
            raise ValueError(f"ChangeNet channels run from 2 inputs to 1 output, got {channels}")
        self.layers = nn.ModuleList(SymmetricConv2d(a, b, kernel_size, padding) for a, b in zip(channels[:-1], channels[1:], strict=True))
        # the residual is ~1e-3 where the correction has work: scaled up so the tanh layers see O(1)
        self.scale = 100.0

    def forward(self, r: torch.Tensor, phi: torch.Tensor) -> torch.Tensor:
        x = torch.cat([self.scale * r, phi], dim=1)
        for k, layer in enumerate(self.layers):
            x = layer(x)
            if k + 1 < len(self.layers):
                x = torch.tanh(x)
        return x / self.scale


def _normalised_residual(phi, history, Gc, lc, h_px, padding, cuts):
    return residual(phi, history, Gc, lc, h_px, padding, cuts) / (Gc / lc + 2.0 * history)


def train_change_net(states: list[tuple[np.ndarray, np.ndarray]], h_px: float, Gc: float, lc: float, padding: str = "replicate",
                     cuts=None, channels=(2, 8, 8, 1), epochs: int = 300, crop: int = 96, crops_per_state: int = 4, lr: float = 3e-3,
                     seed: int = 0, threads: int = 1) -> tuple[ChangeNet, dict]:
    """Train on in-loop states ``[(H, phi_old), ...]`` (H: the equation's history of the increment,
    phi_old: the verified phi before it): per epoch ``crops_per_state`` crops of ``crop`` pixels per
    state, centred where |r| is largest and at random, loss = mean (r of phi_old + delta)^2 on the
    crop's interior (its edge lacks its neighbours). Deterministic for a seed and thread count.
    Returns (model in eval mode, {'loss': per epoch, 'wall_s': training time})."""
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    rng = np.random.default_rng(seed)
    model = ChangeNet(channels, padding=padding).double()
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    data = []
    for history, phi_old in states:
        h = torch.as_tensor(history, dtype=torch.float64)[None, None]
        p = torch.as_tensor(phi_old, dtype=torch.float64)[None, None]
        r = _normalised_residual(p, h, Gc, lc, h_px, padding, cuts)
        data.append((h, p, r))
    ny, nx = states[0][0].shape
    size = min(crop, ny, nx)
    edge = 2 * len(model.layers)   # the network's reach plus the Laplacian's, left out of the loss
    losses, started = [], time.perf_counter()
    for _ in range(epochs):
        batch_h, batch_p, batch_r = [], [], []
        for h, p, r in data:
            worst = np.unravel_index(int(torch.argmax(r.abs())), (ny, nx))
            for c in range(crops_per_state):
                centre = worst if c == 0 else (rng.integers(ny), rng.integers(nx))
                i0 = int(np.clip(centre[0] - size // 2, 0, ny - size))
                j0 = int(np.clip(centre[1] - size // 2, 0, nx - size))
                window = (slice(None), slice(None), slice(i0, i0 + size), slice(j0, j0 + size))
                batch_h.append(h[window]), batch_p.append(p[window]), batch_r.append(r[window])
        h, p, r = torch.cat(batch_h), torch.cat(batch_p), torch.cat(batch_r)
        optimiser.zero_grad()
        after = _normalised_residual(p + model(r, p), h, Gc, lc, h_px, padding, None)[..., edge:-edge, edge:-edge]
        loss = torch.mean(after**2)
        loss.backward()
        optimiser.step()
        losses.append(float(loss.detach()))
    return model.eval(), {"loss": losses, "wall_s": time.perf_counter() - started}


class ChangeNetWarmStart:
    """A verified step's network (warm start ``increment``): its answer's change between calls is the
    network's delta for the new history, fed the check's residual of the last verified phi
    (``verified``: the :class:`ifenn.hybrid.verification.VerifiedInference` it serves)."""

    kernel = "conv2d"

    def __init__(self, model: ChangeNet, Gc: float, lc: float, h_px: float, padding: str = "replicate", cuts=None):
        self.model, self.Gc, self.lc, self.h_px, self.padding, self.cuts = model, Gc, lc, h_px, padding, cuts
        self.verified, self.total = None, None
        self.t_network, self.evaluated_fraction = 0.0, 1.0

    @torch.no_grad()
    def __call__(self, capped: np.ndarray) -> np.ndarray:
        started = time.perf_counter()
        phi = self.verified.phi
        if phi is None or self.total is None:
            self.total = np.zeros(capped.shape) if phi is None else np.array(phi, dtype=np.float64)
        else:
            h = torch.as_tensor(capped, dtype=torch.float64)[None, None]
            p = torch.as_tensor(phi, dtype=torch.float64)[None, None]
            r = _normalised_residual(p, h, self.Gc, self.lc, self.h_px, self.padding, self.cuts)
            self.total = self.total + self.model(r, p)[0, 0].numpy()
        self.t_network = time.perf_counter() - started
        return self.total.copy()
