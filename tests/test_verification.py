"""Verified phase-field step: the residual check is a max-norm certificate against the exact
pixel solution, and the correction brings a spoiled prediction back within the tolerance."""

import numpy as np
import pytest
import torch

from ifenn.hybrid.process_zone import FullInference, ProcessZoneInference
from ifenn.hybrid.verification import VerifiedInference
from ifenn.network.orbit import OrbitEvaluator
from ifenn.network.picnn import PICNN, InputScaling
from ifenn.network.training import synthetic_history
from ifenn.pixel_equation.numpy_backend import PixelEquation, correction_boxes, dilated, normalised_residual, solve_pixel_equation
from ifenn.pixel_equation.torch_backend import residual

GC, LC, H_PX = 2.7, 0.03, 0.0025


@pytest.fixture(scope="module")
def history():
    return synthetic_history(n_px=96, x_tip=0.0)


class Replay:
    """A stand-in network engine: returns the given images in turn."""

    kernel = ""

    def __init__(self, images):
        self.images, self.t_network, self.evaluated_fraction = iter(images), 0.0, 1.0

    def __call__(self, capped):
        return next(self.images)


@pytest.mark.parametrize("padding", ["replicate", "zeros"])
def test_residual_is_the_training_residual_and_zero_at_the_exact_solution(history, padding):
    phi = solve_pixel_equation(history, GC, LC, H_PX, padding, rtol=1e-13)
    r = normalised_residual(phi, history, GC, LC, H_PX, padding)
    assert np.max(np.abs(r)) < 1e-9
    rng = np.random.default_rng(0)
    spoiled = np.clip(phi + 0.05 * rng.standard_normal(phi.shape), 0, 1)
    torch_r = residual(torch.as_tensor(spoiled)[None, None], torch.as_tensor(history)[None, None], GC, LC, H_PX, padding)
    np.testing.assert_allclose(normalised_residual(spoiled, history, GC, LC, H_PX, padding) * (GC / LC + 2 * history),
                               torch_r.numpy()[0, 0], rtol=1e-10, atol=1e-8)


@pytest.mark.parametrize("padding", ["replicate", "zeros"])
def test_normalised_residual_bounds_the_max_error(history, padding):
    """max |phi - exact| <= max |R / (Gc/lc + 2H)| for smooth, rough and one-pixel errors."""
    exact = solve_pixel_equation(history, GC, LC, H_PX, padding, rtol=1e-13)
    ny, nx = history.shape
    y, x = np.mgrid[0:ny, 0:nx]
    rng = np.random.default_rng(1)
    errors = [0.02 * np.ones_like(exact), 0.03 * np.sin(np.pi * x / nx) * np.cos(np.pi * y / ny),
              0.01 * rng.standard_normal(exact.shape), np.where((y == 48) & (x == 10), 0.1, 0.0)]
    for error in errors:
        bound = np.max(np.abs(normalised_residual(exact + error, history, GC, LC, H_PX, padding)))
        assert np.max(np.abs(error)) <= bound * (1 + 1e-9)
    # a uniform error is reported at its size (zero flux; zeros padding reports more at the edges),
    # where the Jacobi-scaled residual R / A_ii would under-report it some 400-fold
    if padding == "replicate":
        assert np.max(np.abs(normalised_residual(exact + errors[0], history, GC, LC, H_PX, padding))) == pytest.approx(0.02, rel=1e-6)


@pytest.mark.parametrize("solver", ["multigrid", "sine_transform"])
@pytest.mark.parametrize("padding", ["replicate", "zeros"])
def test_box_solve_with_the_surroundings_as_boundary_data_is_the_exact_solution(history, padding, solver, monkeypatch):
    """Both correction solvers (the compiled multigrid-preconditioned CG, and the numpy CG with
    the sine-transform preconditioner it falls back to) reproduce the exact pixel solution on
    interior, edge, corner, odd-sized and whole-image boxes."""
    import ifenn.pixel_equation.numpy_backend as numpy_backend

    if solver == "multigrid":
        if numpy_backend.compiled_kernel() is None:
            pytest.skip("the compiled kernel does not build here")
    else:
        monkeypatch.setattr(numpy_backend, "compiled_kernel", lambda: None)
    exact = solve_pixel_equation(history, GC, LC, H_PX, padding, rtol=1e-13)
    equation = PixelEquation(GC, LC, H_PX, padding)
    boxes = [(slice(30, 60), slice(20, 70)), (slice(0, 20), slice(0, 96)), (slice(70, 96), slice(80, 96)),
             (slice(31, 60), slice(19, 70)), (slice(0, 96), slice(0, 96))]
    for box in boxes:
        phi = exact.copy()
        phi[box] = 0.5
        worst, iterations = equation.solve_box(phi, history, box, 1e-10)
        assert worst <= 1e-10 and iterations > 0
        np.testing.assert_allclose(phi, exact, atol=1e-9)
        if solver == "multigrid":  # ~0.1 per V-cycle: 1e-12 of the start in 9-13, where the sine transform needs 25-53
            assert iterations <= 16, (box, iterations)


@pytest.mark.parametrize("margin", [0, 3, 17, 60, 110])
def test_correction_boxes_cover_every_pixel_within_the_margin(margin):
    """The boxes are computed on blocks of margin // 8 pixels: they must still hold every pixel
    within ``margin`` of a failing one (the reach the margin argument asks for)."""
    rng = np.random.default_rng(margin)
    for _ in range(40):
        ny, nx = (int(v) for v in rng.integers(20, 400, 2))
        mask = np.zeros((ny, nx), bool)
        for _ in range(int(rng.integers(1, 5))):
            r, c = int(rng.integers(0, ny)), int(rng.integers(0, nx))
            mask[r:r + int(rng.integers(1, 20)), c:c + int(rng.integers(1, 20))] = True
        cover = np.zeros_like(mask)
        for box in correction_boxes(mask, margin):
            cover[box] = True
        assert not (dilated(mask, margin) & ~cover).any()


def test_the_exact_solution_as_prediction_corrects_nothing(history):
    exact = solve_pixel_equation(history, GC, LC, H_PX, "replicate", rtol=1e-12)
    verified = VerifiedInference(Replay([exact, exact]), PixelEquation(GC, LC, H_PX), tolerance=1e-3)
    for _ in range(2):
        out = verified(history)
        assert verified.corrected_fraction == 0.0 and verified.residual_before < 1e-8
        np.testing.assert_array_equal(out, exact)


def test_a_spoiled_prediction_is_flagged_and_corrected_within_the_tolerance():
    history = synthetic_history(n_px=192, x_tip=0.0)
    exact = solve_pixel_equation(history, GC, LC, H_PX, "replicate", rtol=1e-12)
    rng = np.random.default_rng(2)
    spoiled = exact.copy()
    spoiled[90:105, 80:110] += 0.05 * rng.random((15, 30))   # a wrong patch at the crack tip
    spoiled[5:8, 170:180] -= 0.02                            # and one in the far field
    tolerance = 1e-3
    verified = VerifiedInference(Replay([spoiled]), PixelEquation(GC, LC, H_PX), tolerance=tolerance, margin_lc=2.0)
    out = verified(history)
    assert verified.residual_before > 10 * tolerance
    assert verified.residual_after <= tolerance
    assert np.max(np.abs(out - exact)) <= tolerance
    assert 0.0 < verified.corrected_fraction < 0.5   # local: the rest of the image is left alone
    np.testing.assert_array_equal(out[150:, :40], exact[150:, :40])


def test_the_uncapped_equation_is_certified_while_the_network_sees_the_cap():
    """cap_history false: the network still gets H capped at history_cap, but the step certifies
    FEM's equation on H itself: within the tolerance of the uncapped exact solution, and the crack
    is no longer held at phi <= 2 H_cap / (Gc/lc + 2 H_cap) (0.9991 for 5e4), which it is with the
    published cap_history true."""
    cap = 5.0e4
    history = synthetic_history(n_px=96, x_tip=0.0, band_peak=5.0e6, history_cap=1.0e7)   # a crack far beyond the cap
    assert history.max() > 50 * cap

    class Recording(Replay):
        def __call__(self, capped):
            self.seen = float(capped.max())
            return super().__call__(capped)

    capped_bound = 2 * cap / (GC / LC + 2 * cap)
    for cap_history, exact_history in ((True, np.minimum(history, cap)), (False, history)):
        exact = solve_pixel_equation(exact_history, GC, LC, H_PX, "replicate", rtol=1e-13)
        network = Recording([solve_pixel_equation(np.minimum(history, cap), GC, LC, H_PX, "replicate", rtol=1e-6)])
        verified = VerifiedInference(network, PixelEquation(GC, LC, H_PX), tolerance=1e-4, history_cap=cap, cap_history=cap_history)
        out = verified(history)
        assert network.seen <= cap and verified.residual_after <= 1e-4
        assert np.max(np.abs(out - exact)) <= 1e-4
        if cap_history:
            assert out.max() <= capped_bound + 1e-4
        else:
            assert out.max() > capped_bound + 5e-4 and verified.corrected_fraction > 0


def test_a_spoiled_network_is_corrected_step_after_step_on_a_growing_crack():
    """A PICNN with perturbed weights on a crack that grows: every step ends within the
    tolerance of the exact pixel solution, with the network in full or process-zone
    inference, and the correction warm-started from the last verified phi alone too."""
    torch.manual_seed(0)
    net = PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    with torch.no_grad():
        for layer in net.layers:
            layer.free_weight.mul_(1.0 + 0.3 * torch.randn_like(layer.free_weight))
    tolerance = 1e-3
    engines = {
        "full": lambda: VerifiedInference(FullInference(OrbitEvaluator(net, tile=64).predict, None), PixelEquation(GC, LC, H_PX),
                                          tolerance),
        "zone": lambda: VerifiedInference(ProcessZoneInference(OrbitEvaluator(net, tile=64), None, tolerance=3e-3,
                                                               local_scale=GC / LC), PixelEquation(GC, LC, H_PX), tolerance,
                                          warm_start="network"),
        "previous": lambda: VerifiedInference(None, PixelEquation(GC, LC, H_PX), tolerance, warm_start="previous"),
        # the default: the network's change added to the last verified phi, the network asked again
        # only where the input's local phi moved by 0.1 (the runs' network_tolerance)
        "increment": lambda: VerifiedInference(ProcessZoneInference(OrbitEvaluator(net, tile=64), None, tolerance=0.1,
                                                                    local_scale=GC / LC), PixelEquation(GC, LC, H_PX), tolerance,
                                               warm_start="increment"),
    }
    for name, make in engines.items():
        verified = make()
        previous_history = None
        for k, x_tip in enumerate(np.linspace(-0.05, 0.04, 5)):
            history = synthetic_history(n_px=96, x_tip=x_tip)
            if previous_history is not None:
                history = np.maximum(history, previous_history)
            previous_history = history
            out = verified(history)
            exact = solve_pixel_equation(history, GC, LC, H_PX, "replicate", rtol=1e-12)
            assert verified.residual_after <= tolerance, name
            assert np.max(np.abs(out - exact)) <= tolerance, name
            if k == 0 and name != "previous":
                assert verified.residual_before > 0.05, name  # the spoiled network is flagged
