"""The GPU figures in one run, per device side by side (the CPU, and CUDA where torch sees
one): training of the default PICNN preset, the network on the whole image, and the verified
phase-field step (check + multigrid-PCG correction) on a crack growing across an image of
snt3's size. Self-contained: it needs torch, numpy, scipy, pandas and pyyaml, nothing else (no
dolfinx, no tqdm, no results/; the compiled CPU step also a C compiler): the prepared script for a
GPU machine:

    PYTHONPATH=src OMP_NUM_THREADS=1 python3 benchmarks/device_speed.py [--pixels 600] [--increments 30]
        [--devices cpu cuda] [--training-pixels 400] [--cpu-epochs 50] [--out results/benchmarks/device_speed.csv]

On a lent GPU, ``--devices cuda`` is the preset to run (a few minutes): the CUDA rows only (no CPU
training, no compiled CPU step), training of the whole default preset, the network at 400-4800 px,
and the verified step at snt1's and snt3's image sizes (400 and 600 px). Each timed part on CUDA
is preceded by an untimed warm-up (cuDNN picks its algorithms, the caching allocator fills), so the
numbers are steady-state ones.

What each row is (column ``part``):

* ``training``: the default preset (config ``picnn.preset``) on two synthetic snt-like history
  maps of --training-pixels (``ifenn.network.training.synthetic_history``), seed 0, one torch
  thread on the CPU. On a GPU the whole preset runs; on the CPU --cpu-epochs of it, and
  ``wall_s`` is extrapolated linearly to the preset's epochs (``extrapolated`` = True says so).
* ``network``: the trained network on the whole image (its convolutions, float32), median of 20
  calls after 3 warm-ups, per image size (--gpu-network-sizes too on a GPU); CUDA calls synchronised.
* ``verified``: the verified step (tolerance and settings of config ``ifenn.verification``) on
  --increments images of a crack growing across --pixels x --pixels (h_px = 1 / --pixels, the
  history the running maximum), one step per image: ``compiled`` = the workflow's CPU step (the
  compiled check and correction of :mod:`ifenn.hybrid.verification`, the network in its compiled
  orbit kernel asked again only where the local phi moved by ``network_tolerance``), ``torch`` =
  the workflow's GPU step (:mod:`ifenn.hybrid.device_step`, the network's convolutions on the
  whole image, its answer taken where the compiled step would ask it), each with warm starts ``previous`` (no network) and ``increment`` (the trained
  network's change added to the last verified phi).
  Median ms per step over the increments after the first (the first checks a cold start), CG
  iterations per step, the largest certificate max |r| (<= tolerance, else the step was reported).

FEM's phase-field step is not here (dolfinx runs on the CPU machine only): compare with
``t_phase_field_s`` of FEM in results/benchmarks/phase_field_speed.csv, measured there, and say so.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import yaml

REPO = Path(__file__).resolve().parents[1]


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def crack_sequence(n_px: int, increments: int, lc: float) -> list[np.ndarray]:
    """History images of a crack growing from the left edge to past the centre (running maximum)."""
    from ifenn.network.training import synthetic_history

    images, previous = [], None
    for x_tip in np.linspace(-0.15, 0.1, increments):
        history = synthetic_history(n_px=n_px, h_px=1.0 / n_px, x_tip=float(x_tip), lc=lc)
        previous = history if previous is None else np.maximum(history, previous)
        images.append(previous)
    return images


def training_rows(devices, settings_name: str, n_px: int, cpu_epochs: int, Gc: float, lc: float):
    """Per device: the preset's training wall (a CUDA one after a one-epoch warm-up, untimed)."""
    from ifenn.device import describe
    from ifenn.network.settings import resolve_settings
    from ifenn.network.training import synthetic_history, train_picnn

    h_px = 1.0 / n_px
    maps = [synthetic_history(n_px=n_px, h_px=h_px, x_tip=x, lc=lc) for x in (-0.05, 0.0)]
    rows, models = [], {}
    for device in devices:
        settings = resolve_settings({"preset": settings_name})
        epochs = settings["epochs"] + (settings["full_image_epochs"] if settings["sampling"] == "tiles" else 0)
        short = device.type == "cpu" and cpu_epochs < epochs
        if short:
            settings["epochs"], settings["full_image_epochs"] = cpu_epochs, 0
        if device.type == "cuda":   # warm-up: cuDNN's algorithm choice and the allocator, untimed
            train_picnn(maps, h_px, Gc, lc, {**settings, "epochs": 1, "full_image_epochs": 0}, seed=0, threads=1,
                        progress=False, device=device)
        model, log = train_picnn(maps, h_px, Gc, lc, settings, seed=0, threads=1, progress=False, device=device)
        wall = float(log.wall_s.iloc[-1])
        rows.append({"part": "training", "device": describe(device), "what": f"preset {settings_name}, {n_px} px",
                     "epochs_run": len(log), "wall_s": wall * epochs / len(log) if short else wall, "extrapolated": short,
                     "final_loss": float(log.loss.iloc[-1])})
        models[device.type] = model
        print(f"training {settings_name} on {describe(device)}: {len(log)} epochs in {wall:.1f} s", flush=True)
    return rows, models


def network_rows(model, devices, sizes, gpu_sizes=()):
    from ifenn.device import describe

    rows = []
    for device in devices:
        net = model.to(device).eval()
        for n in list(sizes) + (list(gpu_sizes) if device.type == "cuda" else []):
            history = torch.rand((1, 1, n, n), device=device) * 1e3
            times = []
            with torch.no_grad():
                for k in range(23):
                    _sync(device)
                    started = time.perf_counter()
                    net.phase_field(history)
                    _sync(device)
                    if k >= 3:
                        times.append(time.perf_counter() - started)
            rows.append({"part": "network", "device": describe(device), "what": f"{n} x {n}", "pixels": n * n,
                         "median_ms": 1e3 * float(np.median(times))})
            print(f"network {n} x {n} on {describe(device)}: {rows[-1]['median_ms']:.3g} ms", flush=True)
    model.to("cpu")
    return rows


def verified_rows(model, devices, images, verification: dict, zone: dict, Gc: float, lc: float, history_cap: float, sigma: float,
                  compiled: bool = True):
    """Per variant (the compiled CPU step where ``compiled``, the torch step per device) and warm
    start: the step's median time over a growing crack (the first, cold step untimed; on CUDA
    the whole sequence run once untimed before, as a warm-up)."""
    from ifenn.device import describe
    from ifenn.hybrid.device_step import DeviceVerifiedInference
    from ifenn.hybrid.process_zone import ProcessZoneInference
    from ifenn.hybrid.verification import VerifiedInference
    from ifenn.network.orbit import make_evaluator
    from ifenn.pixel_equation.numpy_backend import PixelEquation
    from ifenn.pixel_equation.torch_backend import TorchPixelEquation

    n_px = images[0].shape[0]
    h_px = 1.0 / n_px
    settings = (verification["tolerance"], verification["margin_lc"], verification["max_rounds"], verification["solve_fraction"])
    rows = []
    variants = ([("compiled", torch.device("cpu"))] if compiled else []) + [("torch", device) for device in devices]
    for (backend, device), warm_start in ((v, w) for v in variants for w in ("previous", "increment")):
        if backend == "compiled":   # the workflow's CPU step: the network in its orbit kernel, asked on the process zone
            network = None
            if warm_start != "previous":
                network = ProcessZoneInference(make_evaluator(model.to("cpu"), "orbit"), sigma, 4.0, verification["network_tolerance"],
                                               zone["refresh_every"], zone["full_fraction"], local_scale=Gc / lc, shape=images[0].shape)
            step = VerifiedInference(network, PixelEquation(Gc, lc, h_px), *settings, warm_start, history_cap)
        else:
            net = None if warm_start == "previous" else model.to(device).eval()
            step = DeviceVerifiedInference(net, TorchPixelEquation(Gc, lc, h_px, device=device), *settings, warm_start, history_cap,
                                           sigma=sigma, network_tolerance=verification["network_tolerance"])
        times, iterations, certificate = [], [], 0.0
        if device.type == "cuda":   # warm-up on a fresh step of the same kind (graphs captured, kernels chosen)
            warm = DeviceVerifiedInference(net, TorchPixelEquation(Gc, lc, h_px, device=device), *settings, warm_start,
                                           history_cap, sigma=sigma, network_tolerance=verification["network_tolerance"])
            for history in images[:3]:
                warm(history)
        for k, history in enumerate(images):
            _sync(device)
            started = time.perf_counter()
            step(history)
            _sync(device)
            if k > 0:
                times.append(time.perf_counter() - started)
                iterations.append(step.solve_iterations)
            certificate = max(certificate, step.residual_after)
        rows.append({"part": "verified", "device": describe(device), "what": f"{backend}, warm start {warm_start}", "pixels": n_px**2,
                     "median_ms": 1e3 * float(np.median(times)), "mean_ms": 1e3 * float(np.mean(times)),
                     "cg_iterations": float(np.mean(iterations)), "max_certificate": certificate,
                     "tolerance": verification["tolerance"]})
        print(f"verified {backend} {warm_start} on {describe(device)}: {rows[-1]['median_ms']:.3g} ms, "
              f"{rows[-1]['cg_iterations']:.2f} CG its, max |r| {certificate:.2e}", flush=True)
    model.to("cpu")
    return rows


def preset(args: argparse.Namespace) -> argparse.Namespace:
    """The defaults that depend on --devices: CUDA alone (the lent GPU's preset) runs no CPU part
    and the verified step at 400 and 600 px; otherwise the compiled CPU step too, at 600 px."""
    cuda_only = args.devices == ["cuda"]
    args.compiled = not cuda_only
    if args.pixels is None:
        args.pixels = [400, 600] if cuda_only else [600]
    return args


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cli.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    cli.add_argument("--pixels", type=int, nargs="+", default=None,
                     help="the verified step's image sides (default 600, snt3's; with --devices cuda alone 400 600)")
    cli.add_argument("--increments", type=int, default=30)
    cli.add_argument("--training-pixels", type=int, default=400, help="the training maps' side (snt1-I: 400)")
    cli.add_argument("--cpu-epochs", type=int, default=50, help="epochs run on the CPU (extrapolated to the preset's)")
    cli.add_argument("--network-sizes", type=int, nargs="+", default=[400, 600, 1200])
    cli.add_argument("--gpu-network-sizes", type=int, nargs="+", default=[2400, 4800], help="more sizes, on a GPU only")
    cli.add_argument("--devices", nargs="+", default=None, choices=["cpu", "cuda"],
                     help="default: cpu, and cuda where torch sees one")
    cli.add_argument("--out", default="results/benchmarks/device_speed.csv")
    args = preset(cli.parse_args())
    from ifenn.device import default_devices, resolve_device
    from ifenn.io import atomic_path

    torch.set_num_threads(1)
    devices = [resolve_device(d, "--devices") for d in args.devices] if args.devices else default_devices()
    config = yaml.safe_load(Path(args.config).read_text())   # read plainly: the config checks need packages a GPU machine lacks
    Gc, lc = config["material"]["Gc"], config["material"]["lc"]
    ifenn = config["ifenn"]
    rows, models = training_rows(devices, config["picnn"]["preset"], args.training_pixels, args.cpu_epochs, Gc, lc)
    model = models.get("cuda", models["cpu"] if "cpu" in models else next(iter(models.values())))
    rows += network_rows(model, devices, args.network_sizes, args.gpu_network_sizes)
    for pixels in args.pixels:
        images = crack_sequence(pixels, args.increments, lc)
        rows += verified_rows(model, devices, images, ifenn["verification"], ifenn["process_zone"], Gc, lc, ifenn["history_cap"],
                              ifenn["smoothing_sigma"], compiled=args.compiled)
    table = pd.DataFrame(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        table.to_csv(tmp, index=False)
    with pd.option_context("display.width", 220, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print(table.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
