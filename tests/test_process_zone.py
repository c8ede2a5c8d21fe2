"""Process-zone inference: windows around changed pixels reproduce full-image inference."""

import numpy as np
import pytest
import torch

from ifenn.hybrid.process_zone import FullInference, ProcessZoneInference
from ifenn.network.orbit import ConvolutionEvaluator, OrbitEvaluator
from ifenn.network.picnn import PICNN, InputScaling


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(3)
    return PICNN(padding="replicate", history_cap=5.0e4, input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()


@pytest.fixture(scope="module")
def model(net):
    return OrbitEvaluator(net, tile=64)


def _growing_histories(shape=(150, 160), steps=12, seed=0):
    """A smooth background plus a 'crack tip' that moves along a row and reaches the image
    edge, with values above the cap on the crack (H grows monotonically, as in a run)."""
    rng = np.random.default_rng(seed)
    ny, nx = shape
    y, x = np.mgrid[0:ny, 0:nx]
    history = 5.0 + rng.random(shape)
    for k in range(steps):
        tip = np.array([ny // 2 + 3, 40 + 10 * k])
        blob = 80.0 * np.exp(-((y - tip[0]) ** 2 + (x - tip[1]) ** 2) / 8.0)
        history = np.maximum(history, blob + np.where((abs(y - tip[0]) < 2) & (x < tip[1]), 1e5, 0.0))
        if k == 7:  # a second, separate zone in a corner
            history[:5, -6:] += 30.0
        yield history.copy()


@pytest.mark.parametrize("sigma", [2.0, None])
@pytest.mark.parametrize("kernel", ["compiled", "torch"])
def test_windows_equal_full_inference_with_zero_tolerance(net, sigma, kernel):
    """Against the network's own convolutions on the whole image, for both orbit paths."""
    full = FullInference(net.predict, sigma, 4.0)
    evaluator = OrbitEvaluator(net, tile=64, kernel=kernel)
    zone = ProcessZoneInference(evaluator, sigma, 4.0, tolerance=0.0, refresh_every=1000, full_fraction=0.9)
    fractions = []
    for history in _growing_histories():
        expected = full(np.clip(history, 0, 5e4))
        got = zone(np.clip(history, 0, 5e4))
        fractions.append(zone.evaluated_fraction)
        np.testing.assert_allclose(got, expected, atol=2e-6, rtol=0)
    assert fractions[0] == 1.0  # the first step evaluates the whole image
    assert 0 < max(fractions[1:]) < 0.9  # later ones only windows


def test_tolerance_bounds_the_stale_inputs(model):
    """With a tolerance, the outputs differ from full inference only through inputs that
    moved by less than 2 x tolerance: small, and zero where nothing changed nearby."""
    full = FullInference(model.predict, 2.0, 4.0)
    zone = ProcessZoneInference(model, 2.0, 4.0, tolerance=1e-2, refresh_every=1000, full_fraction=0.9)
    histories = list(_growing_histories())
    for history in histories:
        got = zone(np.clip(history, 0, 5e4))
    scaled = zone.local_phase_field(np.clip(histories[-1], 0, 5e4))
    assert np.abs(scaled - zone.reference).max() <= 1e-2
    assert np.abs(got - full(np.clip(histories[-1], 0, 5e4))).max() < 0.05


def test_refresh_and_full_fraction_fall_back_to_the_whole_image(model):
    zone = ProcessZoneInference(model, 2.0, 4.0, tolerance=0.0, refresh_every=3, full_fraction=0.9)
    fractions = [zone(np.clip(h, 0, 5e4)) is not None and zone.evaluated_fraction for h in _growing_histories(steps=6)]
    assert fractions[0] == 1.0 and fractions[3] == 1.0 and fractions[1] < 1.0
    everywhere = ProcessZoneInference(model, 2.0, 4.0, tolerance=0.0, full_fraction=0.05)
    everywhere(np.full((40, 40), 3.0))
    everywhere(np.full((40, 40), 4.0))  # every pixel changed: one full evaluation
    assert everywhere.evaluated_fraction == 1.0


@pytest.mark.parametrize("padding", ["zeros", "reflect", "replicate"])
def test_changes_at_the_image_edge_reach_the_padding(padding):
    """Inputs rewritten at an edge or a corner change the padding the next layer reads."""
    torch.manual_seed(4)
    net = PICNN(padding=padding, input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    zone = ProcessZoneInference(OrbitEvaluator(net), None, tolerance=0.0, refresh_every=1000, full_fraction=0.9)
    history = np.random.default_rng(5).lognormal(1.0, 1.0, (60, 50))
    zone(history)
    for box in [(slice(0, 3), slice(10, 20)), (slice(57, 60), slice(47, 50)), (slice(20, 30), slice(0, 2))]:
        history[box] *= 7.0
        np.testing.assert_allclose(zone(history), net.predict(history), atol=2e-6, rtol=0)
        assert zone.evaluated_fraction < 0.5


def test_process_zone_needs_the_orbit_evaluation(net):
    with pytest.raises(ValueError, match="orbit evaluation"):
        ProcessZoneInference(lambda h: h, 2.0)
    with pytest.raises(ValueError, match="orbit evaluation"):
        ProcessZoneInference(ConvolutionEvaluator(net), 2.0)
    with pytest.raises(ValueError, match="circular"):
        ProcessZoneInference(OrbitEvaluator(PICNN(padding="circular")), 2.0)
