"""The verified phase-field step in torch, on the run's device (the GPU's path).

The same step as :class:`ifenn.hybrid.verification.VerifiedInference` (read its module doc for
the equation, the certificate and the warm starts), with every array a torch tensor on one
device: the history goes up once per call, the network (its own convolutions), the Gaussian
smoothing, the residual check and the multigrid-preconditioned correction run there, and the
certified phi comes down once. On the CPU the workflow keeps the compiled step (``device: cpu``
gives today's phi bit for bit); this one is what a CUDA device runs, and the tests run it on the
CPU too, where torch is its own reference.

The correction is the torch backend's multigrid-preconditioned CG
(:mod:`ifenn.pixel_equation.torch_multigrid`, deterministic on a GPU).

What differs from the CPU step, by design for a device where a launch costs more than a pixel:
the residual is recomputed on the whole image (no stale-pixel bookkeeping), the network is
evaluated on the whole image each call (no process zone), and the failing pixels are corrected
in one box per round (their bounding box grown by the margin; the whole image past
``GLOBAL_FRACTION``). The certificate is the same: max |r| <= tolerance over the whole image, or
the step is reported (``residual_after``).

A step's scalars (the certificates, the failing share, the box of the failing pixels) come to the
host together, one transfer each time the loop needs them; the smoothing's kernel and index go up
once per image size.
"""

from __future__ import annotations

import time

import numpy as np
import torch
import torch.nn.functional as F

from ifenn.hybrid.verification import VERIFICATION_DEFAULTS, WARM_STARTS
from ifenn.pixel_equation.torch_backend import TorchPixelEquation, bounding_box, gaussian_smoothing
from ifenn.pixels import box_area


class DeviceVerifiedInference:
    """:class:`ifenn.hybrid.verification.VerifiedInference` on a torch device (module doc): called
    with a history image (numpy, N/mm^2), returns the certified phi (numpy), with the same
    records (``corrected_fraction``, ``residual_before`` / ``residual_after``, ``solve_work``,
    ``t_check``, ``t_correction``, ``t_network``, ``evaluated_fraction``). ``model``: the PICNN
    (on ``device``), or None with ``warm_start='previous'``. ``input_scale``: the network is fed
    that times the (capped) H: a network trained on another material at the same lc / h_px
    (:func:`ifenn.hybrid.runs.network_service`; ``history_cap`` is then the published cap over it)."""

    #: correction boxes over more than this share of the image: the whole image instead (as the
    #: CPU step); on a GPU every correction is on the whole image (``global_fraction`` 0: one
    #: shape, so one captured graph, and a pixel costs less than a launch there)
    GLOBAL_FRACTION = 0.5

    def __init__(self, model, equation: TorchPixelEquation, tolerance: float = VERIFICATION_DEFAULTS["tolerance"],
                 margin_lc: float = VERIFICATION_DEFAULTS["margin_lc"], max_rounds: int = VERIFICATION_DEFAULTS["max_rounds"],
                 solve_fraction: float = VERIFICATION_DEFAULTS["solve_fraction"], warm_start: str = VERIFICATION_DEFAULTS["warm_start"],
                 history_cap: float | None = None, cap_history: bool = VERIFICATION_DEFAULTS["cap_history"],
                 sigma: float | None = None, truncate: float = 4.0, network_tolerance: float | None = None,
                 input_scale: float = 1.0):
        if warm_start not in WARM_STARTS:
            raise ValueError(f"verification warm_start must be one of {WARM_STARTS}, got {warm_start!r}")
        if warm_start != "previous" and model is None:
            raise ValueError("verification warm_start 'network' needs a network")
        if not tolerance > 0:
            raise ValueError(f"verification tolerance must be > 0, got {tolerance}")
        self.model, self.equation, self.tolerance = model, equation, float(tolerance)
        self.input_scale = float(input_scale)
        self.device = equation.device
        self.margin = int(np.ceil(float(margin_lc) * equation.lc / equation.h_px))
        self.max_rounds, self.solve_fraction, self.warm_start = int(max_rounds), float(solve_fraction), warm_start
        self.history_cap = None if history_cap is None else float(history_cap)
        self.cap_history = bool(cap_history)
        self.sigma, self.truncate = sigma, truncate
        # the network's answer is taken only where its input's local phi moved by network_tolerance since
        # it was last taken there, and within the network's reach and the smoothing's radius of such pixels
        self.network_tolerance = network_tolerance
        # (the CPU's process zone rewrites the inputs within the reach of such pixels: the outputs within twice it change)
        reach = sum(layer.kernel_size // 2 for layer in getattr(model, "layers", ()))
        self.zone_radius = 2 * reach + (int(truncate * float(sigma) + 0.5) if sigma else 0)
        self.reference = None   # per pixel, the local phi of the input when the network's answer was last taken
        self.kernel = "" if model is None else "conv2d"
        self.global_fraction = 0.0 if self.device.type == "cuda" else self.GLOBAL_FRACTION
        self.phi = self.prediction = None   # last verified phi, last network prediction (tensors on the device)
        self.t_network = self.t_check = self.t_correction = 0.0
        self.evaluated_fraction = self.corrected_fraction = self.failing_fraction = 0.0
        self.residual_before = self.residual_after = 0.0
        self.solve_iterations, self.solve_work = 0, 0.0

    def start_from(self, phi: np.ndarray) -> None:
        if self.phi is None:
            self.phi = torch.as_tensor(np.asarray(phi, dtype=np.float64), device=self.device).clone()

    @torch.no_grad()
    def _network(self, capped: torch.Tensor) -> torch.Tensor:
        started = time.perf_counter()
        dtype = next(self.model.parameters()).dtype
        raw = self.model.phase_field((capped * self.input_scale).to(dtype)[None, None])[0, 0].to(torch.float64)
        out = gaussian_smoothing(raw, self.sigma, self.truncate)
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        self.t_network, self.evaluated_fraction = time.perf_counter() - started, 1.0
        return out

    def _candidate(self, capped: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        if self.warm_start == "previous":
            self.t_network, self.evaluated_fraction = 0.0, 0.0
            if self.phi is None:   # the local solution 2H / (Gc/lc + 2H)
                return self.equation.local_solution(history)
            return self.phi.clone()
        prediction = self._network(capped)
        local = self.equation.local_solution(capped)
        if self.prediction is None or self.phi is None:
            self.prediction, self.reference = prediction, local
            return prediction.clone()
        if self.network_tolerance is not None:   # the CPU's process zone, as a mask on the whole image's answer
            moved = (local - self.reference).abs() > self.network_tolerance
            self.reference = torch.where(moved, local, self.reference)
            radius = self.zone_radius
            zone = F.max_pool2d(moved[None, None].to(torch.float32), 2 * radius + 1, stride=1, padding=radius)[0, 0] > 0
            prediction = torch.where(zone, prediction, self.prediction)
            self.evaluated_fraction = float(zone.float().mean())
        if self.warm_start == "network":
            candidate = torch.where(prediction != self.prediction, prediction, self.phi)
        else:   # "increment": the network's change added to the last verified phi
            candidate = self.phi + (prediction - self.prediction)
        self.prediction = prediction
        return candidate

    @torch.no_grad()
    def __call__(self, history: np.ndarray) -> np.ndarray:
        history = torch.as_tensor(np.asarray(history, dtype=np.float64), device=self.device)   # up once
        network_input = history if self.history_cap is None else torch.clamp(history, max=self.history_cap)
        if self.cap_history:
            history = network_input
        phi = self._candidate(network_input, history)
        started = time.perf_counter()
        equation = self.equation
        residual = equation.residual(phi, history)
        failing = residual.abs() > self.tolerance
        self.residual_before, self.failing_fraction = torch.stack([residual.abs().max(), failing.double().mean()]).tolist()
        self.t_check = time.perf_counter() - started
        started = time.perf_counter()
        corrected = torch.zeros(history.shape, dtype=torch.bool, device=self.device)
        self.solve_iterations, self.solve_work = 0, 0.0
        margin, size = self.margin, history.numel()
        for _ in range(self.max_rounds):
            box = bounding_box(failing, margin)
            if box is None:
                break
            if box_area(box) > self.global_fraction * size:
                box = (slice(0, history.shape[0]), slice(0, history.shape[1]))
            _, iterations = equation.solve_box(phi, history, box, self.solve_fraction * self.tolerance)
            self.solve_iterations += iterations
            self.solve_work += iterations * box_area(box) / size
            corrected[box] = True
            residual = equation.residual(phi, history)
            failing = residual.abs() > self.tolerance
            margin *= 2
        self.residual_after, self.corrected_fraction = torch.stack([residual.abs().max(), corrected.double().mean()]).tolist()
        out = phi.cpu().numpy()   # down once
        self.t_correction = time.perf_counter() - started
        self.phi = phi
        return out
