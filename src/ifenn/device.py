"""Where the network's tensors live: the config's ``device`` (``auto``: CUDA when torch sees
one, else the CPU; ``cpu``; ``cuda``), resolved once per process and handed to training and
inference. The FEM stays on PETSc (CPU). The verified step runs where the network does: on the
CPU its compiled check and correction (:mod:`ifenn.hybrid.verification`), on a GPU the whole step
in torch (:mod:`ifenn.hybrid.device_step`: H up once, phi down once). The exact pixel solver
(a sparse direct solve) stays on the CPU.

The setting is not part of a run's spec (a spec says what is computed, the device where): a
run's provenance.json records the device that computed it (:func:`describe`) and the float32
precision its convolutions and matrix products ran at (:func:`float32_precision`).

Full float32 precision: torch runs float32 cuDNN convolutions in TF32 by default on Ampere and
later GPUs (10 mantissa bits). The network's phi would then differ from the CPU's by ~1e-4, and the
float32 V-cycle, whose stencil sums nearly cancelling terms, would lose precision (CG would need
more iterations). :func:`resolve_device` sets IEEE float32 for cuDNN convolutions and CUDA matrix
products, once, for every device, before anything runs.
"""

from __future__ import annotations

import os

DEVICES = ("auto", "cpu", "cuda")


def resolve_device(setting="auto", key: str = "device"):
    """The torch device of a ``device`` setting (None: auto; a torch device is returned as it is,
    so a device resolved once can be handed down through the same calls); an unknown value or
    ``cuda`` without a CUDA device is refused naming ``key``, the value and what is allowed."""
    import torch

    full_float32_precision()
    if isinstance(setting, torch.device):
        return setting
    setting = "auto" if setting is None else setting
    if setting not in DEVICES:
        raise ValueError(f"config key '{key}': {setting!r}; allowed: {list(DEVICES)}")
    if setting == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"config key '{key}': 'cuda', but torch {torch.__version__} sees no CUDA device; "
                         "allowed here: 'auto' or 'cpu'")
    if setting == "auto":
        setting = "cuda" if torch.cuda.is_available() else "cpu"
    if setting == "cuda":
        # deterministic cuBLAS (training runs under torch.use_deterministic_algorithms)
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    return torch.device(setting)


#: torch's float32 precision settings (new API only: mixing it with the legacy allow_tf32 flags is
#: an error in the pinned torch) -> the value that means full IEEE float32
FLOAT32_SETTINGS = {"cudnn_conv": ("cudnn", "conv"), "cuda_matmul": ("cuda", "matmul")}


def full_float32_precision() -> None:
    """IEEE float32 (no TF32) for cuDNN convolutions and CUDA matrix products (module doc)."""
    import torch

    for backend, op in FLOAT32_SETTINGS.values():
        getattr(getattr(torch.backends, backend), op).fp32_precision = "ieee"


def float32_precision() -> dict:
    """The float32 precision in force: {'cudnn_conv': 'ieee' | 'tf32' | ..., 'cuda_matmul': ...}."""
    import torch

    return {name: getattr(getattr(torch.backends, backend), op).fp32_precision for name, (backend, op) in FLOAT32_SETTINGS.items()}


def describe(device) -> str:
    """A device in words for provenance and figure labels: 'cpu' or 'cuda (NVIDIA H200)'."""
    import torch

    device = torch.device(device)
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    return device.type


def network_device(spec: dict, device="auto"):
    """The torch device of a run whose predictor is the network (``device`` resolved once, here,
    and handed down); None for the other predictors, which then never import torch."""
    return resolve_device(device) if spec.get("predictor") == "picnn" else None


def device_record(device) -> dict:
    """provenance.json's record of where the network ran ({} without a network)."""
    return {} if device is None else {"network_device": describe(device), "float32_precision": float32_precision()}


def default_devices() -> list:
    """The devices a benchmark compares side by side: the CPU, and CUDA where torch sees one."""
    import torch

    return [torch.device("cpu")] + ([resolve_device("cuda")] if torch.cuda.is_available() else [])
