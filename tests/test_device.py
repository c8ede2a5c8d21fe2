"""The device setting (ifenn.device): one setting for training and inference, refused when it
cannot hold, and the same numbers on a GPU as on the CPU (to float tolerance) where one is present."""

import subprocess
import sys

import numpy as np
import pytest
import torch

from ifenn.device import describe, device_record, network_device, resolve_device
from ifenn.network.picnn import load_picnn, save_picnn
from ifenn.network.training import synthetic_history, train_picnn
from ifenn.pixel_equation.torch_backend import residual
from ifenn.pixels import PixelGrid, SlitCuts

GC, LC, H_PX = 2.7, 0.03, 0.0025
TINY = {"epochs": 5, "channels": (1, 4, 1), "lr": 1e-2}
CUDA = torch.cuda.is_available()
NEEDS_CUDA = pytest.mark.skipif(not CUDA, reason=f"torch {torch.__version__} sees no CUDA device on this machine")


def test_settings_resolve_and_bad_ones_name_the_key():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type == ("cuda" if CUDA else "cpu")
    with pytest.raises(ValueError, match=r"config key 'device': 'tpu'; allowed: \['auto', 'cpu', 'cuda'\]"):
        resolve_device("tpu")
    if not CUDA:
        with pytest.raises(ValueError, match="sees no CUDA device"):
            resolve_device("cuda")
    assert describe("cpu") == "cpu"
    assert device_record(torch.device("cpu")) == {"network_device": "cpu", "float32_precision": {"cudnn_conv": "ieee", "cuda_matmul": "ieee"}}
    # runs without the network never resolve a device (nor import torch for it)
    assert network_device({"predictor": "exact_pixel"}, "cuda") is None and device_record(None) == {}


def test_resolving_a_device_sets_full_float32_precision(monkeypatch):
    """torch's default runs float32 cuDNN convolutions in TF32 (10 mantissa bits) on Ampere and later
    GPUs; once a device is resolved, convolutions and matrix products run in IEEE float32, on every
    device, and provenance says so."""
    from ifenn.device import float32_precision

    torch.backends.cudnn.conv.fp32_precision = "tf32"
    torch.backends.cuda.matmul.fp32_precision = "tf32"
    assert float32_precision() == {"cudnn_conv": "tf32", "cuda_matmul": "tf32"}
    resolve_device("cpu")
    assert float32_precision() == {"cudnn_conv": "ieee", "cuda_matmul": "ieee"}
    torch.backends.cudnn.conv.fp32_precision = "tf32"
    resolve_device(torch.device("cpu"))   # a device resolved before, handed down: the setting holds too
    assert float32_precision()["cudnn_conv"] == "ieee" and torch.get_float32_matmul_precision() == "highest"


def test_cuda_without_one_is_refused_before_any_job(paper_config):
    """device: cuda on a machine whose torch sees no CUDA device stops the config check, naming the
    key (a run would otherwise fail at its first network call); accepted where one is present."""
    import copy

    from ifenn.config import ConfigError, validate_config

    config = {**copy.deepcopy(paper_config), "device": "cuda"}
    if CUDA:
        assert validate_config(config)["device"] == "cuda"
    else:
        with pytest.raises(ConfigError, match="config key 'device': 'cuda', but torch .* sees no CUDA device"):
            validate_config(config)


def test_the_config_checks_no_longer_import_the_network():
    """config -> network.settings -> schema: the checks resolve a training preset without torch
    (the circle config -> training -> picnn -> config is gone)."""
    code = ("import sys, yaml, ifenn.config as c; "
            "c.validate_config(yaml.safe_load((c.REPO / 'config' / 'config.yaml').read_text()), petsc_names=False); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stderr


def test_training_on_a_named_device_is_the_same_training(tmp_path):
    """The device is handed down (a setting or a resolved device, same weights); the model comes
    back on the CPU and a saved one loads onto the device asked for."""
    history = [synthetic_history(n_px=32, x_tip=0.0)]
    a, log_a = train_picnn(history, H_PX, GC, LC, TINY, seed=3, threads=1, progress=False, device="cpu")
    b, log_b = train_picnn(history, H_PX, GC, LC, TINY, seed=3, threads=1, progress=False, device=torch.device("cpu"))
    assert a.device.type == "cpu" and np.array_equal(log_a.loss, log_b.loss)
    for p, q in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(p, q)
    save_picnn(a, tmp_path / "m.pt", H_PX, GC, LC, "hash")
    loaded, _ = load_picnn(tmp_path / "m.pt", device="cpu")
    np.testing.assert_array_equal(loaded.predict(history[0]), a.predict(history[0]))


@NEEDS_CUDA
def test_cuda_gives_the_cpu_numbers_to_float_tolerance(tmp_path):
    """On a GPU: the network's phi, the pixel residual with slit cuts, and a short training agree
    with the CPU's to float tolerance (float32 network, float64 residual)."""
    history = synthetic_history(n_px=48, x_tip=0.0)
    model, _ = train_picnn([history], H_PX, GC, LC, TINY, seed=0, threads=1, progress=False, device="cpu")
    on_gpu, _ = train_picnn([history], H_PX, GC, LC, TINY, seed=0, threads=1, progress=False, device="cuda")
    for p, q in zip(model.parameters(), on_gpu.parameters(), strict=True):
        np.testing.assert_allclose(p.detach().numpy(), q.detach().numpy(), rtol=1e-3, atol=1e-5)
    save_picnn(model, tmp_path / "m.pt", H_PX, GC, LC, "hash")
    gpu_model, _ = load_picnn(tmp_path / "m.pt", device="cuda")
    assert gpu_model.device.type == "cuda"
    np.testing.assert_allclose(gpu_model.predict(history), model.predict(history), atol=1e-5)
    scene = {"domain": {"x": [-0.5, 0.5], "y": [-0.5, 0.5]}, "elements": [24, 24],  # pixels: 48 x 48, h_px = 1/48
             "notches": [{"kind": "slit", "start": [-0.5, 0.0], "end": [0.0, 0.0]}]}
    cuts = SlitCuts.for_scene(scene, PixelGrid.for_scene(scene), "replicate")
    phi = np.random.default_rng(0).random((1, 1, 48, 48))
    h = np.asarray(history)[None, None]
    cpu = residual(torch.as_tensor(phi), torch.as_tensor(h), GC, LC, 1 / 48, "replicate", cuts)
    gpu = residual(torch.as_tensor(phi, device="cuda"), torch.as_tensor(h, device="cuda"), GC, LC, 1 / 48, "replicate", cuts)
    np.testing.assert_allclose(gpu.cpu().numpy(), cpu.numpy(), rtol=1e-12, atol=1e-9)
