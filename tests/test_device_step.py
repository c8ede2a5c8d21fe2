"""The verified step in torch (ifenn.hybrid.device_step), the GPU's path, run here on the CPU: the
same algorithm as the compiled correction (same iterates to round-off, same iteration counts), the
same certificate, and on CUDA (where present) the same phi to float tolerance."""

import numpy as np
import pytest
import scipy.ndimage
import torch

from ifenn.hybrid.device_step import DeviceVerifiedInference
from ifenn.hybrid.verification import VerifiedInference
from ifenn.network.picnn import PICNN, InputScaling
from ifenn.network.training import synthetic_history
from ifenn.pixel_equation.numpy_backend import PixelEquation, compiled_kernel, solve_pixel_equation
from ifenn.pixel_equation.torch_backend import TorchPixelEquation, gaussian_smoothing
from ifenn.pixels import PixelGrid, SlitCuts

GC, LC = 2.7, 0.03
CUDA = torch.cuda.is_available()


def _slit_scene(n_px: int, start=(-0.12, 0.0), end=(0.0, 0.0)):
    """A square of n_px x n_px pixels (h_px = 0.24 / n_px), slit from the left edge, and its cuts."""
    scene = {"domain": {"x": [-0.12, 0.12], "y": [-0.12, 0.12]}, "elements": [n_px // 2, n_px // 2],
             "notches": [{"kind": "slit", "start": list(start), "end": list(end)}]}
    grid = PixelGrid.for_scene(scene)
    return grid.h_px, SlitCuts.for_scene(scene, grid, "replicate")


def _shear_history(n_px: int) -> np.ndarray:
    """A history field that differs across the slit (a shear-like band above it, none below)."""
    y, x = (np.mgrid[:n_px, :n_px] + 0.5) / n_px - 0.5
    band = 5.0e4 * np.exp(-(((y - 0.02) / 0.03) ** 2)) * (y > 0) * np.exp(-np.maximum(x, 0) / 0.1)
    return band + 20.0 * np.random.default_rng(0).random((n_px, n_px))


def test_gaussian_smoothing_is_scipys():
    image = np.random.default_rng(1).random((37, 53))
    for sigma in (2.0, 1.3):
        np.testing.assert_allclose(gaussian_smoothing(torch.as_tensor(image), sigma, 4.0).numpy(),
                                   scipy.ndimage.gaussian_filter(image, sigma, truncate=4.0, mode="reflect"), atol=1e-14)


@pytest.mark.parametrize("padding", ["replicate", "zeros"])
def test_the_port_is_the_compiled_correction(padding):
    """Residual and box solves (whole image, a box inside it, a box on the image edge), with the
    slits' cuts on every level: the torch port takes the compiled kernel's iterations to its iterates
    (its V-cycle runs in float32 too, so to round-off, not bit for bit)."""
    if compiled_kernel() is None:
        pytest.skip("the compiled kernel did not build here: nothing to compare the port with")
    n = 96
    h_px, cuts = _slit_scene(n)
    history = _shear_history(n)
    phi = 0.3 * np.random.default_rng(2).random((n, n))
    compiled, port = PixelEquation(GC, LC, h_px, padding, cuts), TorchPixelEquation(GC, LC, h_px, padding, cuts)
    whole = (slice(0, n), slice(0, n))
    np.testing.assert_allclose(port.residual(torch.as_tensor(phi), torch.as_tensor(history)).numpy(),
                               compiled.residual_on(phi, history, whole), atol=1e-12)
    for box in (whole, (slice(20, 70), slice(10, 80)), (slice(0, 50), slice(0, 61))):
        a, b = phi.copy(), torch.as_tensor(phi.copy())
        worst_a, iterations_a = compiled.solve_box(a, history, box, 1e-6)
        worst_b, iterations_b = port.solve_box(b, torch.as_tensor(history), box, 1e-6)
        assert iterations_a == iterations_b and 0 < iterations_b < 15
        assert worst_b <= 1e-6
        np.testing.assert_allclose(b.numpy(), a, atol=1e-10)


def test_the_port_solves_the_cut_equation_to_its_certificate():
    """Whatever the compiled kernel: a box solve to max |r| <= t is within t of the exact solution
    of the cut pixel equation (the sparse solver's), across the slit too."""
    n = 64
    h_px, cuts = _slit_scene(n)
    history = _shear_history(n)
    exact = solve_pixel_equation(history, GC, LC, h_px, "replicate", rtol=1e-13, cuts=cuts)
    phi = torch.zeros((n, n), dtype=torch.float64)
    port = TorchPixelEquation(GC, LC, h_px, "replicate", cuts)
    worst, iterations = port.solve_box(phi, torch.as_tensor(history), (slice(0, n), slice(0, n)), 1e-5)
    assert worst <= 1e-5 and iterations < 20   # the V-cycle's about tenfold reduction per iteration
    assert np.max(np.abs(phi.numpy() - exact)) <= 1e-5
    # the slit holds: above it the band's damage (0.999), right below it only what reaches round the
    # tip (0.18; 0.99 without the cuts)
    row = n // 2
    assert phi[row, 5] - phi[row - 1, 5] > 0.7


def test_the_sums_over_repeated_indices_need_no_atomics(monkeypatch):
    """On a GPU, index_add over repeated indices is an atomic add (its order, so its bits, vary from
    run to run). The step sums them as gathers in a fixed order instead: the restriction is the
    prolongation's transpose (<P^T r, x> = <r, P x>), and the cut equation solves with index_add
    unavailable, to the same phi and iterations as before, bit for bit on a rerun."""
    from ifenn.pixel_equation.torch_multigrid import DeviceMultigrid

    n = 64
    h_px, cuts = _slit_scene(n)
    history = torch.as_tensor(_shear_history(n))
    grid = DeviceMultigrid((n, n - 3), (True, False, True, True), [None], "cpu")
    rng = np.random.default_rng(1)
    for k in range(len(grid.levels) - 1):
        r = torch.as_tensor(rng.random(grid.levels[k].shape), dtype=torch.float32)
        x = torch.as_tensor(rng.random(grid.levels[k + 1].shape), dtype=torch.float32)
        lhs, rhs = float(torch.sum(grid._restrict(k, r) * x)), 0.25 * float(torch.sum(r * grid._prolong(k, x)))
        assert abs(lhs - rhs) <= 1e-5 * abs(rhs), k

    def solve():
        phi = torch.zeros((n, n), dtype=torch.float64)
        port = TorchPixelEquation(GC, LC, h_px, "replicate", cuts)
        worst, iterations = port.solve_box(phi, history, (slice(0, n), slice(0, n)), 1e-5)
        return phi, worst, iterations, port.residual(phi, history)

    reference = solve()

    def atomic(*args, **kwargs):
        raise AssertionError("index_add: an atomic add on a GPU")

    monkeypatch.setattr(torch.Tensor, "index_add_", atomic)
    monkeypatch.setattr(torch.Tensor, "index_add", atomic)
    monkeypatch.setattr(torch, "index_add", atomic)
    first, second = solve(), solve()
    assert first[2] == reference[2] and first[1] <= 1e-5
    assert torch.equal(first[0], second[0]) and torch.equal(first[3], second[3])


def _spoiled_network():
    torch.manual_seed(0)
    net = PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    with torch.no_grad():
        for layer in net.layers:
            layer.free_weight.mul_(1.0 + 0.3 * torch.randn_like(layer.free_weight))
    return net


def test_the_device_step_serves_another_material_through_the_scaled_history():
    """The network trained on one material serves another at the same lc / h_px fed H lc/Gc in its
    own units (input_scale): the pixel equation's dimensionless form is the same, so the step on
    material B's H = H_A Gc_B / Gc_A gives material A's phi, step after step, to round-off, with the
    same CG iterations."""
    h_px, tolerance, gc_b = 0.0025, 1e-3, 0.09
    scale = GC / gc_b
    net = _spoiled_network()
    own = DeviceVerifiedInference(net, TorchPixelEquation(GC, LC, h_px), tolerance, warm_start="increment", sigma=2.0,
                                  history_cap=45.0)
    other = DeviceVerifiedInference(net, TorchPixelEquation(gc_b, LC, h_px), tolerance, warm_start="increment", sigma=2.0,
                                    history_cap=45.0 / scale, input_scale=scale)
    previous = None
    for x_tip in np.linspace(-0.05, 0.04, 4):
        history = synthetic_history(n_px=96, x_tip=x_tip)
        previous = history = history if previous is None else np.maximum(history, previous)
        phi_a, phi_b = own(history), other(history / scale)
        assert np.max(np.abs(phi_a - phi_b)) < 1e-9 and own.solve_iterations == other.solve_iterations
        assert other.residual_after <= tolerance and own.evaluated_fraction == other.evaluated_fraction


@pytest.mark.parametrize(("warm_start", "as_on_a_gpu"), [("increment", False), ("network", False), ("previous", False),
                                                        ("increment", True)])
def test_a_spoiled_network_is_certified_step_after_step_on_a_growing_crack(warm_start, as_on_a_gpu):
    """The device step with a perturbed PICNN on a growing crack: every step within the
    tolerance of the exact pixel solution. ``as_on_a_gpu``: as a GPU runs it, every correction on
    the whole image and every CG iteration the captured graph's (the next direction prepared
    before the certificate is read)."""
    h_px, tolerance = 0.0025, 1e-3
    net = _spoiled_network() if warm_start != "previous" else None
    equation = TorchPixelEquation(GC, LC, h_px)
    device_step = DeviceVerifiedInference(net, equation, tolerance, warm_start=warm_start, sigma=2.0)
    if as_on_a_gpu:
        device_step.global_fraction = 0.0
        fused = TorchPixelEquation._grid

        def grid(self, box, shape):
            cg = fused(self, box, shape)
            cg.fused = True
            return cg

        equation._grid = grid.__get__(equation)
    previous = None
    for k, x_tip in enumerate(np.linspace(-0.05, 0.04, 4)):
        history = synthetic_history(n_px=96, x_tip=x_tip)
        if previous is not None:
            history = np.maximum(history, previous)
        previous = history
        out = device_step(history)
        exact = solve_pixel_equation(history, GC, LC, h_px, "replicate", rtol=1e-12)
        assert device_step.residual_after <= tolerance and np.max(np.abs(out - exact)) <= tolerance
        assert device_step.t_check > 0 and device_step.solve_work >= 0
        if k == 0 and warm_start != "previous":
            assert device_step.residual_before > 0.05 and device_step.corrected_fraction > 0   # flagged and corrected
        if as_on_a_gpu and device_step.solve_iterations:
            assert device_step.corrected_fraction == 1.0


def test_the_uncapped_equation_and_the_capped_network_input():
    """cap_history false certifies H itself while the network sees min(H, cap), as the CPU step."""
    cap = 5.0e4
    history = synthetic_history(n_px=64, x_tip=0.0, band_peak=5.0e6, history_cap=1.0e7)
    seen = []

    class Recording(torch.nn.Module):
        def phase_field(self, capped):
            seen.append(float(capped.max()))
            return torch.zeros_like(capped)

        def parameters(self):
            return iter([torch.zeros(1)])

    for cap_history, exact_history in ((True, np.minimum(history, cap)), (False, history)):
        step = DeviceVerifiedInference(Recording(), TorchPixelEquation(GC, LC, 0.0025), 1e-4, history_cap=cap, cap_history=cap_history)
        out = step(history)
        exact = solve_pixel_equation(exact_history, GC, LC, 0.0025, "replicate", rtol=1e-13)
        assert seen[-1] <= cap and np.max(np.abs(out - exact)) <= 1e-4


@pytest.mark.skipif(not CUDA, reason=f"torch {torch.__version__} sees no CUDA device on this machine")
def test_cuda_gives_the_cpu_step_to_float_tolerance():
    """On a GPU: the same residual to 1e-12, and a certified step within 2 x the tolerance of the
    CPU's certified phi (both within the tolerance of the exact one)."""
    n = 96
    h_px, cuts = _slit_scene(n)
    history = _shear_history(n)
    phi = 0.3 * np.random.default_rng(2).random((n, n))
    cpu, gpu = TorchPixelEquation(GC, LC, h_px, "replicate", cuts), TorchPixelEquation(GC, LC, h_px, "replicate", cuts, "cuda")
    np.testing.assert_allclose(gpu.residual(torch.as_tensor(phi, device="cuda"), torch.as_tensor(history, device="cuda")).cpu().numpy(),
                               cpu.residual(torch.as_tensor(phi), torch.as_tensor(history)).numpy(), atol=1e-12)
    compiled = VerifiedInference(None, PixelEquation(GC, LC, h_px, "replicate", cuts), 1e-3, warm_start="previous")
    on_gpu = DeviceVerifiedInference(None, gpu, 1e-3, warm_start="previous")
    np.testing.assert_allclose(on_gpu(history), compiled(history), atol=2e-3)
    assert on_gpu.residual_after <= 1e-3


def test_the_device_benchmark_runs_without_dolfinx(tmp_path):
    """benchmarks/device_speed.py, the prepared script for a GPU machine (which has torch but no
    dolfinx, PETSc or jsonschema), on a small scene: every part runs with those modules blocked,
    and the torch step takes the compiled step's CG iterations to the same certificate."""
    import subprocess
    import sys

    import pandas as pd

    from ifenn.config import REPO

    blocked = ("import sys, runpy\nfor m in ('dolfinx', 'petsc4py', 'mpi4py', 'jsonschema', 'ufl', 'h5py', 'tqdm', 'matplotlib', "
               "'meshio', 'snakemake'): sys.modules[m] = None\n")
    script = REPO / "benchmarks" / "device_speed.py"
    out = tmp_path / "device_speed.csv"
    args = ["--pixels", "120", "--increments", "4", "--training-pixels", "64", "--cpu-epochs", "3", "--network-sizes", "64",
            "--devices", "cpu", "--out", str(out)]
    code = blocked + f"sys.argv = [{str(script)!r}] + {args!r}\nrunpy.run_path({str(script)!r}, run_name='__main__')\n"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                          env={**__import__("os").environ, "PYTHONPATH": str(REPO / "src")})
    assert done.returncode == 0, done.stderr[-3000:]
    table = pd.read_csv(out)
    assert set(table.part) == {"training", "network", "verified"}
    verified = table[table.part == "verified"].set_index("what")
    assert (verified.max_certificate <= verified.tolerance).all()
    for warm_start in ("previous", "increment") if compiled_kernel() is not None else ():   # the compiled step's own algorithm
        compiled, port = verified.loc[f"compiled, warm start {warm_start}"], verified.loc[f"torch, warm start {warm_start}"]
        assert compiled.cg_iterations == port.cg_iterations and compiled.max_certificate == pytest.approx(port.max_certificate, rel=1e-3)


def test_the_gpu_preset_of_the_device_benchmark():
    """``--devices cuda`` alone is the lent GPU's preset: no CPU part (training, compiled step), the
    verified step at snt1's and snt3's image sizes; otherwise the compiled step is timed beside."""
    import argparse
    import importlib.util

    from ifenn.config import REPO

    spec = importlib.util.spec_from_file_location("device_speed", REPO / "benchmarks" / "device_speed.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    gpu = module.preset(argparse.Namespace(devices=["cuda"], pixels=None))
    assert gpu.pixels == [400, 600] and not gpu.compiled
    both = module.preset(argparse.Namespace(devices=None, pixels=None))
    assert both.pixels == [600] and both.compiled
    assert module.preset(argparse.Namespace(devices=["cuda"], pixels=[1200])).pixels == [1200]
