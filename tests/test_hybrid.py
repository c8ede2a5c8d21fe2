"""IFENN on the FEM loop: the exact pixel solver must track FEM; the known defects
(zero padding, smoothing) must show as measurable residual force."""

import copy

import numpy as np
import pandas as pd
import pytest
from conftest import quick_fem_run

from ifenn.config import IFENN_OPTIONS
from ifenn.hybrid.runs import run_ifenn


@pytest.fixture(scope="module")
def fem_run(quick_config, tmp_path_factory):
    return quick_fem_run(quick_config, tmp_path_factory, "snt1-I", "hybrid")


def _ifenn(fem_run, quick_config, name, **options):
    spec, tmp, _ = fem_run
    spec = copy.deepcopy(spec)
    spec.update({k: quick_config["ifenn"][k] for k in IFENN_OPTIONS}, name=name, **options)
    return pd.DataFrame(run_ifenn(spec, tmp / "mesh.xdmf", tmp / "fem", None, tmp / name, progress=False))


def _l2(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def test_exact_pixel_solver_tracks_fem(fem_run, quick_config):
    """Zero-flux pixel Laplacian, no smoothing: force curve within 1 % (L2) of FEM, the
    specimen is cut (final force within 10 % of FEM's, as a fraction of the peak)."""
    _, _, fem = fem_run
    hybrid = _ifenn(fem_run, quick_config, "exact", predictor="exact_pixel", smoothing_sigma=None, pixel_padding="replicate")
    switch = int(fem.increment[fem.phi_max > quick_config["ifenn"]["switch_phi_max"]].iloc[0])
    assert list(hybrid.hybrid_active) == [0] * switch + [1] * (len(fem) - switch)
    # pre-switch rows are FEM's, copied, not recomputed
    pd.testing.assert_frame_equal(hybrid.iloc[:switch][fem.columns], fem.iloc[:switch], check_dtype=False)
    assert (hybrid.t_inference_s.iloc[switch:] > 0).all() and (hybrid.t_inference_s.iloc[:switch] == 0).all()
    assert _l2(hybrid.reaction_force, fem.reaction_force) < 0.01
    peak = fem.reaction_force.max()
    assert abs(hybrid.reaction_force.iloc[-1] - fem.reaction_force.iloc[-1]) < 0.1 * peak


def test_zero_padding_and_smoothing_leave_residual_force(fem_run, quick_config):
    """The released script's zero padding acts like phi = 0 outside the image, and the
    Gaussian smoothing lowers phi_max: both keep load on a specimen FEM has cut."""
    _, _, fem = fem_run
    final_fem = fem.reaction_force.iloc[-1]
    zeros = _ifenn(fem_run, quick_config, "zeros", predictor="exact_pixel", smoothing_sigma=None, pixel_padding="zeros")
    smooth = _ifenn(fem_run, quick_config, "smooth", predictor="exact_pixel", smoothing_sigma=2.0, pixel_padding="replicate")
    assert zeros.reaction_force.iloc[-1] > 1.5 * final_fem
    assert smooth.reaction_force.iloc[-1] > 1.5 * final_fem
    assert smooth.phi_max.iloc[-1] < zeros.phi_max.iloc[-1]


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_verified_ifenn_with_a_poor_network_tracks_fem(fem_run, quick_config, tmp_path, backend, monkeypatch):
    """An untrained (random) PICNN, checked and corrected every increment: the corrected
    phase field is the exact pixel solution within the tolerance, so the run tracks FEM as the
    exact pixel solver does: force within 1 % (L2), cut through like FEM's, and every
    increment ends with max |r| within the tolerance. ``torch``: the step a GPU runs
    (ifenn.hybrid.device_step), here on the CPU, through the same run."""
    import torch

    import ifenn.hybrid.runs
    from ifenn.hybrid.device_step import DeviceVerifiedInference

    monkeypatch.setattr(ifenn.hybrid.runs, "verified_step_backend", lambda device: backend)
    device_calls = []
    step = DeviceVerifiedInference.__call__
    monkeypatch.setattr(DeviceVerifiedInference, "__call__", lambda self, history: device_calls.append(1) or step(self, history))

    from ifenn.network.picnn import PICNN, InputScaling, save_picnn

    spec, tmp, fem = fem_run
    torch.manual_seed(0)
    net = PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    model = tmp_path / "random.pt"
    save_picnn(net, model, spec["scene"]["domain"]["x"][1] / spec["scene"]["elements"][0], 2.7, 0.15, "test")
    verified = {**quick_config["ifenn"]["verification"], "enabled": True}
    run_spec = copy.deepcopy(spec)
    run_spec.update({k: quick_config["ifenn"][k] for k in IFENN_OPTIONS}, name="verified", smoothing_sigma=None,
                    irreversible=False, pixel_padding="replicate", inference="process_zone",
                    process_zone=quick_config["ifenn"]["process_zone"], verification=verified)
    hybrid = pd.DataFrame(run_ifenn(run_spec, tmp / "mesh.xdmf", tmp / "fem", model, tmp_path / "verified", progress=False))
    active = hybrid[hybrid.hybrid_active == 1]
    assert len(active) > 0 and len(device_calls) == (len(active) if backend == "torch" else 0)
    assert (active.verify_residual_after <= verified["tolerance"]).all()
    assert active.verify_residual_before.iloc[0] > 10 * verified["tolerance"]  # the random network is flagged
    assert (active.verify_corrected_fraction > 0).any()
    assert _l2(hybrid.reaction_force, fem.reaction_force) < 0.01
    peak = fem.reaction_force.max()
    assert abs(hybrid.reaction_force.iloc[-1] - fem.reaction_force.iloc[-1]) < 0.05 * peak


@pytest.mark.parametrize("evaluation", ["orbit", "convolution"])
def test_the_run_owns_the_history_cap(quick_config, tmp_path, evaluation):
    """The network is capped at the run's history_cap, not at the one stored with it: at cap 1e6
    its input reaches 1e6 (a network saved with the published 5e4), and past the cap it is held there."""
    import torch

    from ifenn.hybrid.runs import network_inference
    from ifenn.network.picnn import PICNN, InputScaling, load_picnn, save_picnn

    torch.manual_seed(0)
    net = PICNN(history_cap=5e4, input_scaling=InputScaling("log", 0.01, 45.0), init_gain=0.3).eval()
    path = tmp_path / "net.pt"
    save_picnn(net, path, 0.0125, 2.7, 0.15, "test")
    assert load_picnn(path)[0].history_cap == 5e4
    spec = {**{k: quick_config["ifenn"][k] for k in IFENN_OPTIONS}, "predictor": "picnn", "inference": "full",
            "evaluation": evaluation, "smoothing_sigma": None, "history_cap": 1e6}
    inference = network_inference(spec, path, 0.0125, (8, 8), "cpu")
    def uncapped(value):   # the network on the scaled input value, no cap of its own
        return net(net.input_scaling(torch.full((1, 1, 8, 8), value, dtype=torch.float32))).detach().double().numpy()[0, 0]

    for value, seen in ((1e6, 1e6), (2e6, 1e6), (5e4, 5e4)):
        np.testing.assert_allclose(inference(np.full((8, 8), value)), uncapped(seen), rtol=1e-5, atol=1e-6)
    # a network held at 5e4 would answer 1e6 as it answers 5e4: the two must differ for the check to mean anything
    assert np.abs(uncapped(1e6) - uncapped(5e4)).max() > 1e-3
