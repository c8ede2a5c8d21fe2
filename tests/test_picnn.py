"""PICNN: symmetry, pixel physics, exact pixel solver, training and persistence."""

import numpy as np
import pytest
import torch

from ifenn.network.orbit import ConvolutionEvaluator, OrbitEvaluator
from ifenn.network.picnn import PICNN, InputScaling, SymmetricConv2d, load_picnn, save_picnn
from ifenn.network.training import PRESETS, make_tiles, resolve_settings, score_picnn, synthetic_history, train_picnn
from ifenn.pixel_equation.numpy_backend import gaussian_smoothing, solve_pixel_equation
from ifenn.pixel_equation.torch_backend import laplacian_9pt, physics_loss, residual

GC, LC, H_PX = 2.7, 0.03, 0.0025


def as_batch(field: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(field, dtype=torch.float64)[None, None]


@pytest.fixture(scope="module")
def small_history() -> np.ndarray:
    """A 64x64 snt-like history map (crack band, tip field, far field of a few N/mm^2)."""
    return synthetic_history(n_px=64, x_tip=0.0)


# --------------------------------------------------------------------------- symmetry
def test_symmetric_kernel_has_six_free_values_and_all_square_symmetries():
    torch.manual_seed(0)
    layer = SymmetricConv2d(3, 4, kernel_size=5)
    assert layer.free_weight.shape == (4, 3, 6)
    kernel = layer.kernel().detach()
    assert kernel.shape == (4, 3, 5, 5)
    for image in (kernel.flip(-1), kernel.flip(-2), kernel.transpose(-1, -2), torch.rot90(kernel, 1, (-2, -1))):
        assert torch.equal(image, kernel)
    # the 6 values are exactly the distinct entries of each kernel
    assert all(torch.unique(kernel[o, i]).numel() == 6 for o in range(4) for i in range(3))
    # default network: 6 values per kernel, 1*24 + 24*24 + 24*24 + 24*1 kernels
    assert PICNN().n_free_parameters() == 6 * (24 + 576 + 576 + 24)


@pytest.mark.parametrize("padding", ["zeros", "replicate"])
def test_network_is_equivariant_to_rotations_and_mirrors(padding):
    torch.manual_seed(1)
    model = PICNN(padding=padding, input_scaling=InputScaling("log1p", 1.0)).double()
    history = np.random.default_rng(0).uniform(0.0, 3.0e3, size=(23, 31))  # a rectangle
    phi = model.predict(history)
    assert phi.shape == history.shape and 0.0 < phi.min() and phi.max() < 1.0
    for transform in (np.fliplr, np.flipud, np.transpose, np.rot90, lambda a: np.rot90(a, 3)):
        np.testing.assert_allclose(model.predict(transform(history).copy()), transform(phi), atol=1e-12)


def test_network_is_local_with_receptive_radius_eight():
    torch.manual_seed(2)
    model = PICNN().double()
    assert model.receptive_radius == 8
    history = synthetic_history(n_px=60, x_tip=0.0)
    full = model.predict(history)
    crop = model.predict(history[10:50, 5:45])  # interior of the crop: >= 8 pixels from its edge
    np.testing.assert_allclose(crop[8:-8, 8:-8], full[18:42, 13:37], atol=1e-12)
    assert np.abs(crop[0] - full[10, 5:45]).max() > 1e-6  # the crop edge does differ


def test_log_input_scaling_centres_the_half_broken_history():
    """x = log((H + ref) / (centre + ref)): 0 at H = centre = Gc/(2 lc), where 2H/(Gc/lc + 2H) = 1/2."""
    scaling = InputScaling("log", reference=0.01, centre=GC / (2 * LC))
    x = scaling(torch.tensor([0.0, GC / (2 * LC), 5.0e4], dtype=torch.float64))
    assert x[1].item() == pytest.approx(0.0, abs=1e-12)
    assert x[0].item() == pytest.approx(np.log(0.01 / 45.01)) and x[2].item() == pytest.approx(np.log(50000.01 / 45.01))


def test_zero_input_gives_one_half():
    """No biases: H = 0 maps to phi = 0.5 exactly, whatever the weights."""
    model = PICNN()
    np.testing.assert_array_equal(model.predict(np.zeros((9, 12))), 0.5)


# --------------------------------------------------------------------------- pixel physics
def test_laplacian_of_a_quadratic_is_exact_in_the_interior():
    h_px = 0.01
    y, x = np.meshgrid(np.arange(20) * h_px, np.arange(25) * h_px, indexing="ij")
    phi = x**2 + 3.0 * y**2 + 0.7 * x * y + 0.2 * x - y
    for padding in ("zeros", "replicate"):
        lap = laplacian_9pt(as_batch(phi), h_px, padding)[0, 0].numpy()
        np.testing.assert_allclose(lap[1:-1, 1:-1], 8.0, rtol=1e-9)


@pytest.mark.parametrize("padding", ["zeros", "replicate"])
def test_exact_pixel_solution_has_near_zero_loss(small_history, padding):
    phi = solve_pixel_equation(small_history, GC, LC, H_PX, padding)
    assert 0.0 < phi.min() and phi.max() < 1.0 and phi.max() > 0.95  # a crack
    history = as_batch(small_history)
    loss_exact = physics_loss(as_batch(phi), history, GC, LC, H_PX, padding).item()
    loss_zero = physics_loss(torch.zeros_like(history), history, GC, LC, H_PX, padding).item()
    loss_half = physics_loss(torch.full_like(history, 0.5), history, GC, LC, H_PX, padding).item()
    assert loss_zero > 1e5 and loss_half > 1e5  # N/mm^2: 2H ~ 1e5 on the crack
    assert loss_exact < 1e-6 * min(loss_zero, loss_half)


@pytest.mark.parametrize("padding", ["zeros", "replicate"])
def test_pixel_solver_matches_a_direct_solve(small_history, padding):
    import scipy.sparse
    import scipy.sparse.linalg

    from ifenn.pixel_equation.numpy_backend import laplacian_matrix

    history = small_history[:, :50]  # a rectangle
    matrix = scipy.sparse.diags(GC / LC + 2 * history.ravel()) - GC * LC / H_PX**2 * laplacian_matrix(64, 50, padding)
    direct = scipy.sparse.linalg.spsolve(matrix.tocsc(), 2 * history.ravel()).reshape(history.shape)
    np.testing.assert_allclose(solve_pixel_equation(history, GC, LC, H_PX, padding), direct, atol=1e-9)
    warm = solve_pixel_equation(history, GC, LC, H_PX, padding, initial_guess=direct)
    np.testing.assert_allclose(warm, direct, atol=1e-9)


def test_uniform_history_gives_the_local_solution():
    """Zero flux and uniform H: Lap(phi) = 0, phi = 2H / (Gc/lc + 2H) at every pixel."""
    history = np.full((17, 13), 45.0)
    phi = solve_pixel_equation(history, GC, LC, H_PX, "replicate")
    np.testing.assert_allclose(phi, 90.0 / (GC / LC + 90.0), rtol=1e-8)
    # zero padding (phi = 0 beyond the image) pulls the boundary down
    phi_zero = solve_pixel_equation(history, GC, LC, H_PX, "zeros")
    assert phi_zero[0, 0] < 0.5 * phi_zero[8, 6] and phi_zero[8, 6] < 0.5


def test_residual_units_and_sign():
    """phi = 0 everywhere: R = -2H exactly (N/mm^2)."""
    history = as_batch(np.random.default_rng(3).uniform(0, 100, (5, 6)))
    r = residual(torch.zeros_like(history), history, GC, LC, H_PX)
    torch.testing.assert_close(r, -2.0 * history)


# --------------------------------------------------------------------------- smoothing
def test_gaussian_smoothing_keeps_constants_and_has_radius_eight():
    np.testing.assert_allclose(gaussian_smoothing(np.full((30, 40), 0.7)), 0.7, rtol=1e-12)
    delta = np.zeros((41, 41))
    delta[20, 20] = 1.0
    smooth = gaussian_smoothing(delta, sigma=2.0)
    assert smooth[20, 28] > 0.0 and smooth[20, 29] == 0.0  # truncate 4 sigma: radius 8
    np.testing.assert_allclose(smooth.sum(), 1.0, rtol=1e-12)
    batch = gaussian_smoothing(np.stack([delta, 2 * delta]))
    np.testing.assert_allclose(batch[1], 2 * smooth)


# --------------------------------------------------------------------------- tiles
@pytest.mark.parametrize("padding", ["zeros", "replicate"])
def test_tiles_reproduce_the_full_image_loss(small_history, padding):
    """Crops with 9 pixels of context reproduce the full-image residual on their tiles."""
    torch.manual_seed(4)
    model = PICNN(padding=padding).double()
    capped = np.minimum(small_history, model.history_cap)[None]
    tiles, in_zone = make_tiles(capped, tile_size=20, context=9, process_zone_history=GC / LC, process_zone_margin_px=4)
    assert in_zone.any() and not in_zone.all()
    assert tiles.weight.sum().item() == small_history.size  # the tiles partition the image
    full = physics_loss(model.phase_field(as_batch(capped[0])), as_batch(capped[0]), GC, LC, H_PX, padding)
    tiled = physics_loss(model.phase_field(tiles.history), tiles.history, GC, LC, H_PX, padding, tiles.weight)
    torch.testing.assert_close(tiled, full, rtol=1e-10, atol=0.0)


# --------------------------------------------------------------------------- training
TINY = {"epochs": 15, "lr": 1e-2, "channels": (1, 6, 6, 1), "log_every": 1}


def test_a_few_epochs_lower_the_loss(small_history):
    model, log = train_picnn([small_history], H_PX, GC, LC, TINY, seed=0, threads=1, progress=False)
    assert list(log.columns[:4]) == ["epoch", "loss", "wall_s", "stage"] and len(log) == 15
    assert log.loss.iloc[-1] < 0.7 * log.loss.iloc[0]


def test_process_zone_training_runs_and_lowers_the_loss(small_history):
    # the paper's loss throughout (warm-up = all epochs), so that its value can be compared
    settings = dict(PRESETS["tiles"], **TINY, tile_size=16, full_image_epochs=2, residual_scaling_warmup=17)
    settings.update(process_zone_tiles=None, far_field_tiles=2, lr_final=1e-3)
    history = as_batch(np.minimum(small_history, 5e4)).float()
    torch.manual_seed(0)  # the initial weights of train_picnn(seed=0)
    untrained = PICNN(channels=TINY["channels"], input_scaling=InputScaling("log1p", 1.0))
    model, log = train_picnn([small_history], H_PX, GC, LC, settings, seed=0, threads=1, progress=False)
    assert set(log.stage) == {"crops", "full"} and len(log) == 17
    with torch.no_grad():
        before = physics_loss(untrained.phase_field(history), history, GC, LC, H_PX).item()
        after = physics_loss(model.phase_field(history), history, GC, LC, H_PX).item()
    assert after < 0.7 * before


def test_training_is_reproducible(small_history):
    runs = [train_picnn([small_history], H_PX, GC, LC, TINY, seed=s, threads=1, progress=False)[0] for s in (7, 7, 8)]
    for key, value in runs[0].state_dict().items():
        assert torch.equal(value, runs[1].state_dict()[key])
    assert not torch.equal(runs[0].layers[0].free_weight, runs[2].layers[0].free_weight)


def test_settings_presets():
    assert resolve_settings({"preset": "released"})["lr"] == 1e-3
    text = resolve_settings({"preset": "text"})
    assert (text["lr"], text["epochs"], text["sampling"]) == (1e-4, 10000, "full")
    assert resolve_settings({"preset": "tiles", "epochs": 3})["epochs"] == 3
    with pytest.raises(KeyError):
        resolve_settings({"learning_rate": 1.0})


# --------------------------------------------------------------------------- persistence, scoring
def test_save_load_roundtrip(tmp_path, small_history):
    torch.manual_seed(5)
    model = PICNN(padding="replicate", history_cap=1e5, input_scaling=InputScaling("log1p", 2.0))
    path = tmp_path / "picnn.pt"
    extra = {"settings": resolve_settings({"preset": "tiles"}), "training_increments": [300, 310]}
    save_picnn(model, path, h_px=H_PX, Gc=GC, lc=LC, config_hash="abc123", extra=extra)
    loaded, meta = load_picnn(path)
    np.testing.assert_array_equal(loaded.predict(small_history), model.predict(small_history))
    assert meta["config_hash"] == "abc123" and meta["h_px"] == H_PX and meta["extra"] == extra
    assert loaded.input_scaling == InputScaling("log1p", 2.0) and loaded.history_cap == 1e5
    assert loaded.padding == "replicate" and [p.name for p in tmp_path.iterdir()] == ["picnn.pt"]


def test_score_picnn_against_itself_and_the_exact_solution(small_history):
    torch.manual_seed(6)
    model = PICNN()
    own = model.predict(small_history)
    (perfect,) = score_picnn(model, [small_history], [own])
    assert perfect["mae_all"] == 0.0 and perfect["mae_crack"] == 0.0
    exact = solve_pixel_equation(small_history, GC, LC, H_PX)
    (untrained,) = score_picnn(model, [small_history], [exact])
    assert untrained["n_broken"] > 0 and untrained["mae_all"] > 0.05


@pytest.mark.parametrize("kernel", ["compiled", "torch"])
@pytest.mark.parametrize("padding", ["zeros", "replicate", "reflect"])
def test_orbit_evaluation_is_the_same_network(padding, kernel):
    """Orbit sums + GEMM (ifenn.network.orbit) give the convolutions' outputs, on whole images (tiled)
    and on boxes at the corners, edges and inside; also for other kernel and channel sizes."""
    torch.manual_seed(1)
    net = PICNN(padding=padding, input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    history = np.random.default_rng(2).lognormal(1.0, 2.0, (70, 83))
    reference = net.predict(history)
    assert np.abs(reference - 0.5).max() > 0.2  # a network far from trivial
    evaluator = OrbitEvaluator(net, tile=29, kernel=kernel)
    np.testing.assert_allclose(evaluator.predict(history), reference, atol=2e-6, rtol=0)
    for box in [(slice(0, 5), slice(0, 9)), (slice(3, 40), slice(70, 83)), (slice(20, 41), slice(30, 52)), (slice(69, 70), slice(8, 9))]:
        np.testing.assert_allclose(evaluator.predict_box(history, box), reference[box], atol=2e-6, rtol=0)
        np.testing.assert_allclose(ConvolutionEvaluator(net).predict_box(history, box), reference[box], atol=2e-6, rtol=0)
    wide = PICNN(channels=(1, 5, 9, 2, 1), kernel_size=7, padding=padding, init_gain=2.0).eval()
    np.testing.assert_allclose(OrbitEvaluator(wide, tile=16, kernel=kernel).predict(history[:40, :30]), wide.predict(history[:40, :30]),
                               atol=2e-6, rtol=0)


def test_compiled_dilation_is_the_square_maximum_filter():
    """The kernel's mask dilation (process-zone reach) against scipy's maximum filter."""
    import scipy.ndimage

    net = PICNN().eval()
    compiled, reference = OrbitEvaluator(net, kernel="compiled"), OrbitEvaluator(net, kernel="torch")
    mask = np.random.default_rng(7).random((37, 53)) > 0.97
    mask[0, 0] = mask[-1, 20] = mask[10, -1] = True   # at the edges
    for r in (1, 2, 5):
        expected = scipy.ndimage.maximum_filter(mask, size=2 * r + 1, mode="constant", cval=False)
        np.testing.assert_array_equal(compiled.dilate(mask, r), expected)
        np.testing.assert_array_equal(reference.dilate(mask, r), expected)
    assert compiled.dilate(mask, 2).sum() > 4 * mask.sum()


def test_kernel_can_be_turned_off_and_is_rebuilt_where_the_cache_is(monkeypatch, tmp_path):
    """IFENN_KERNEL=0 gives the torch path (and "compiled" then says it is not there); a new
    cache directory gets its own build, which computes what the torch path computes."""
    from ifenn.network import orbit_kernel

    net = PICNN(init_gain=2.0).eval()
    history = np.random.default_rng(3).lognormal(1.0, 2.0, (20, 30))
    try:
        monkeypatch.setenv("IFENN_KERNEL", "0")
        orbit_kernel.load.cache_clear()
        assert OrbitEvaluator(net).kernel == "torch"
        with pytest.raises(RuntimeError, match="not available"):
            OrbitEvaluator(net, kernel="compiled")
        monkeypatch.setenv("IFENN_KERNEL", "1")
        monkeypatch.setenv("IFENN_KERNEL_CACHE", str(tmp_path))
        orbit_kernel.load.cache_clear()
        evaluator = OrbitEvaluator(net)
        assert evaluator.kernel == "compiled" and len(list(tmp_path.glob("orbit_kernel-*.so"))) == 1
        np.testing.assert_allclose(evaluator.predict(history), OrbitEvaluator(net, kernel="torch").predict(history), atol=2e-6, rtol=0)
    finally:
        orbit_kernel.load.cache_clear()


def test_torch_comes_before_dolfinx_and_only_where_needed():
    """torch is imported before dolfinx's stack in any process that loads both (else dolfinx's
    BLAS serves torch.mm, ~13x slower), and not at all by the figure and table adapters."""
    import subprocess
    import sys

    def modules(code):
        return subprocess.run([sys.executable, "-c", f"{code}; import sys; print(' '.join(sys.modules))"], check=True,
                              capture_output=True, text=True).stdout.split()

    loaded = modules("import ifenn.fem.mesh; import dolfinx")
    assert loaded.index("torch") < loaded.index("dolfinx")
    loaded = modules("import ifenn.config; from petsc4py import PETSc")
    assert loaded.index("torch") < loaded.index("petsc4py")
    assert "torch" not in modules("import ifenn.studies.figures, ifenn.run_files, ifenn.config")
