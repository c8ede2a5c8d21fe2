"""PICNN accuracy against training wall time: the default preset and the paper's two.

Trains on the history maps of the training increments (snt1-I, increments 300 and
310) and scores the prediction (no smoothing) against the FEM phi of the same increments:
mean absolute error over all pixels and over crack pixels (FEM phi > 0.05), plus the error
against the exact solution of the pixel equation the loss drives toward (the network's own
target; it differs from FEM by the pixel stencil and the boundary padding).

* tiles (the default): trained for its full number of epochs.
* released (lr 1e-3, 5,000 full-image epochs) and text (lr 1e-4, 10,000): trained for a
  few hundred epochs only (--short-epochs); their wall time for the full schedule is
  extrapolated linearly from the measured time per epoch, their accuracy is the one
  reached after the short run (not extrapolated). The output says so.

Falls back to a synthetic stand-in (``ifenn.network.training.synthetic_history``, scored against the
exact pixel solution) when the FEM fields do not exist. Timing is honest wall time on this
machine with --threads torch threads; other jobs running at the same time slow it down.

Every preset trains on each device of --devices (default: the CPU, and CUDA where torch sees
one), side by side in one table (column ``device``, by name).

    .venv/bin/python benchmarks/picnn_training.py [--fields results/fem/snt1-I/fields.h5]
        [--increments 300 310] [--threads 2] [--short-epochs 200] [--presets ...] [--devices cpu cuda] [--csv out.csv]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from ifenn.config import REPO, load_config
from ifenn.device import default_devices, describe, resolve_device
from ifenn.network.training import PRESETS, SCORE_CRACK_PHI, resolve_settings, synthetic_history, train_picnn
from ifenn.pixel_equation.numpy_backend import solve_pixel_equation


def read_fields(path: Path, increments: list[int]) -> tuple[float, list[np.ndarray], list[np.ndarray]]:
    """(h_px, history maps, FEM phi maps) of the given 1-based increments of a fields.h5."""
    from ifenn import run_files

    states = run_files.read_states(path, increments, keys=run_files.MAP_KEYS)
    return float(run_files.fields_attrs(path)["h_px"]), [s["history"] for s in states], [s["phase_field_gp"] for s in states]


def make_monitor(history_maps, reference_maps, exact_maps):
    """Callable model -> accuracy numbers per increment (used at checkpoints of training)."""

    def monitor(model) -> dict:
        row = {}
        for k, (history, reference, exact) in enumerate(zip(history_maps, reference_maps, exact_maps, strict=True)):
            phi = model.predict(history)
            error = np.abs(phi - reference)
            row[f"mae_all_{k}"] = error.mean()
            row[f"mae_crack_{k}"] = error[reference > SCORE_CRACK_PHI].mean()
            row[f"mae_pixel_exact_{k}"] = np.abs(phi - exact).mean()
            row[f"max_phi_{k}"] = phi.max()
        return row

    return monitor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fields", type=Path, default=REPO / "results/fem/snt1-I/fields.h5")
    parser.add_argument("--increments", type=int, nargs="+", default=[300, 310])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--short-epochs", type=int, default=200, help="epochs run for released/text")
    parser.add_argument("--checkpoints", type=int, default=5, help="accuracy rows per preset")
    parser.add_argument("--presets", nargs="+", default=["tiles", "released", "text"], choices=list(PRESETS))
    parser.add_argument("--devices", nargs="+", default=None, choices=["cpu", "cuda"],
                        help="where to train (default: cpu, and cuda where torch sees one)")
    parser.add_argument("--csv", type=Path, default=None, help="also write the table here")
    args = parser.parse_args()
    devices = [resolve_device(d, "--devices") for d in args.devices] if args.devices else default_devices()

    material = load_config(REPO / "config/config.yaml")["material"]
    Gc, lc = material["Gc"], material["lc"]
    if args.fields.exists():
        h_px, history_maps, fem_maps = read_fields(args.fields, args.increments)
        source = f"FEM fields {args.fields.relative_to(REPO) if args.fields.is_relative_to(REPO) else args.fields}"
    else:
        h_px = 0.0025
        history_maps = [synthetic_history(h_px=h_px, x_tip=x_tip, lc=lc) for x_tip in (-0.05, 0.0)]
        fem_maps = None
        source = "SYNTHETIC stand-in (no FEM fields found); reference = exact pixel solution"

    rows = []
    for device, preset in ((device, preset) for device in devices for preset in args.presets):
        settings = resolve_settings({"preset": preset})
        full_epochs = settings["epochs"] + (settings["full_image_epochs"] if settings["sampling"] == "tiles" else 0)
        short = preset != "tiles"
        if short:
            settings["epochs"] = min(args.short_epochs, settings["epochs"])
        run_epochs = settings["epochs"] + (settings["full_image_epochs"] if settings["sampling"] == "tiles" else 0)
        capped = [np.minimum(h, settings["history_cap"]) for h in history_maps]
        exact = [solve_pixel_equation(h, Gc, lc, h_px, settings["laplacian_padding"]) for h in capped]
        reference = fem_maps if fem_maps is not None else exact
        monitor = make_monitor(history_maps, reference, exact)
        started = time.perf_counter()
        _, log = train_picnn(
            history_maps, h_px, Gc, lc, settings, seed=args.seed, threads=args.threads, progress=True,
            monitor=monitor, monitor_every=max(run_epochs // args.checkpoints, 1), device=device,
        )
        print(f"{preset} on {describe(device)}: {run_epochs} epochs, {time.perf_counter() - started:.1f} s including scoring")
        checkpoints = log.dropna(subset=["mae_all_0"]).copy()
        checkpoints.insert(0, "preset", preset)
        checkpoints.insert(0, "device", describe(device))
        checkpoints["epochs_of_preset"] = full_epochs
        per_epoch = log.wall_s.iloc[-1] / len(log)
        checkpoints["extrapolated_wall_s"] = per_epoch * full_epochs if short else np.nan
        rows.append(checkpoints)

    table = pd.concat(rows, ignore_index=True)
    columns = ["device", "preset", "epoch", "wall_s", "extrapolated_wall_s"]
    for k in range(len(history_maps)):
        columns += [f"mae_all_{k}", f"mae_crack_{k}", f"mae_pixel_exact_{k}", f"max_phi_{k}"]
    pd.set_option("display.width", 250)
    print()
    print(f"PICNN training benchmark: data = {source}, increments {args.increments} (index 0, 1),")
    print(f"torch threads = {args.threads}, seed = {args.seed}. wall_s = training time up to that epoch.")
    print("mae_all / mae_crack: |phi - reference| over all pixels / pixels with reference phi > 0.05;")
    print("mae_pixel_exact: against the exact solution of the pixel equation; no smoothing.")
    for preset in args.presets:
        if preset != "tiles":
            n = resolve_settings({"preset": preset})["epochs"]
            print(
                f"NOTE {preset}: only {min(args.short_epochs, n)} of its {n} epochs were run; "
                "extrapolated_wall_s = measured s/epoch x full epochs; its accuracy is the one "
                "reached after the short run, NOT an extrapolation."
            )
    print(table[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.csv is not None:
        table[columns].to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
