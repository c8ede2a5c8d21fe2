"""Figures (matplotlib, Agg). Each function writes one file atomically and returns nothing."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .io import atomic_path  # noqa: E402


def _save(fig, path) -> None:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    plt.close(fig)


def mesh_figure(mesh, scene: dict, name: str, path) -> None:
    """The scene: element grid (every line up to 60 per direction, else every k-th), slit
    notches (red), history notches (orange), fixed components (hatched edges) and loaded
    components (arrows)."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    fig, ax = plt.subplots(figsize=(6, 6 * (y1 - y0) / (x1 - x0) + 0.6))
    stride_x = max(1, mesh.nx // 60)
    stride_y = max(1, mesh.ny // 60)
    for i in range(0, mesh.nx + 1, stride_x):
        ax.plot([x0 + i * mesh.h] * 2, [y0, y1], color="0.8", lw=0.3)
    for j in range(0, mesh.ny + 1, stride_y):
        ax.plot([x0, x1], [y0 + j * mesh.h] * 2, color="0.8", lw=0.3)
    ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], color="k", lw=1)
    for slit in mesh.slits:
        (ax_, ay), (bx, by) = slit["snapped"]
        ax.plot([ax_, bx], [ay, by], color="red", lw=2.5, label=f"slit ({slit['n_twins']} twin nodes)")
    for notch in scene.get("notches", []):
        if notch["kind"] == "history":
            (ax_, ay), (bx, by) = notch["start"], notch["end"]
            ax.plot([ax_, bx], [ay, by], color="orange", lw=2.5, ls="--", label="history notch")
    span = max(x1 - x0, y1 - y0)
    edges = {"left": ((x0, y0), (x0, y1), (-1, 0)), "right": ((x1, y0), (x1, y1), (1, 0)),
             "bottom": ((x0, y0), (x1, y0), (0, -1)), "top": ((x0, y1), (x1, y1), (0, 1))}
    for edge, components in scene["boundary"].items():
        (ax_, ay), (bx, by), (nx_, ny_) = edges[edge]
        fixed = [c for c, k in components.items() if k == "fixed"]
        loaded = [c for c, k in components.items() if k == "load"]
        if fixed:
            ax.plot([ax_, bx], [ay, by], color="tab:blue", lw=5, alpha=0.5)
            ax.text((ax_ + bx) / 2 + nx_ * 0.06 * span, (ay + by) / 2 + ny_ * 0.06 * span,
                    "u" + ",".join(fixed) + " = 0", ha="center", va="center", color="tab:blue", fontsize=8)
        for c in loaded:
            dx, dy = (0.06 * span, 0) if c == "x" else (0, 0.06 * span)
            for t in np.linspace(0.1, 0.9, 5):
                px, py = ax_ + t * (bx - ax_), ay + t * (by - ay)
                ax.annotate("", xy=(px + dx, py + dy), xytext=(px, py), arrowprops={"arrowstyle": "->", "color": "tab:green"})
            ax.text((ax_ + bx) / 2 + nx_ * 0.12 * span, (ay + by) / 2 + ny_ * 0.12 * span, f"u{c} = u",
                    ha="center", va="center", color="tab:green", fontsize=8)
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=False))
    if unique:
        ax.legend(unique.values(), unique.keys(), loc="upper right", fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlim(x0 - 0.18 * span, x1 + 0.18 * span)
    ax.set_ylim(y0 - 0.18 * span, y1 + 0.18 * span)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{name}: {mesh.nx} x {mesh.ny} Q1 elements, h = {mesh.h:.4g} mm, {len(mesh.points)} nodes")
    _save(fig, path)


def force_displacement_figure(curves: dict, path, title: str = "", u_max: float | None = None) -> None:
    """Reaction force against prescribed displacement; ``curves`` maps label -> DataFrame
    with columns u and reaction_force."""
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for label, frame in curves.items():
        frame = frame if u_max is None else frame[frame["u"] <= u_max + 1e-15]
        ax.plot(frame["u"], frame["reaction_force"], label=label, lw=1.4)
    ax.set_xlabel("prescribed displacement u (mm)")
    ax.set_ylabel("reaction force (N/mm)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, path)


def _gauss_point_coordinates(data: dict) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (mm) of the Gauss point behind each pixel: in element (i, j) of size
    h = 2 h_px the 2x2 points sit at (i + 1/2 -+ 1/(2 sqrt 3)) h, the lower one in the even pixel."""
    h = 2.0 * float(data["h_px"])
    offset = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
    x = float(data["x0"]) + (np.arange(int(data["nx_px"])) // 2 + offset[np.arange(int(data["nx_px"])) % 2]) * h
    y = float(data["y0"]) + (np.arange(int(data["ny_px"])) // 2 + offset[np.arange(int(data["ny_px"])) % 2]) * h
    return np.meshgrid(x, y)


def _extent(data: dict) -> list[float]:
    x0, y0, h = float(data["x0"]), float(data["y0"]), float(data["h_px"])
    return [x0, x0 + int(data["nx_px"]) * h, y0, y0 + int(data["ny_px"]) * h]


def training_data_figure(data: dict, path, zoom_half_width_px: int = 40) -> None:
    """H at the Gauss points (scatter, zoomed on the crack tip) beside the pixel map (whole
    image), one row per training increment; log colour scale shared per row."""
    from matplotlib.colors import LogNorm

    gx, gy = _gauss_point_coordinates(data)
    n = len(data["increment"])
    fig, axes = plt.subplots(n, 2, figsize=(12, 5 * n), squeeze=False, gridspec_kw={"wspace": 0.35})
    for k in range(n):
        history = np.maximum(data["history"][k], 1e-3)
        norm = LogNorm(vmin=max(history.min(), 1e-2), vmax=history.max())
        # zoom on the crack tip: the cracked pixel (phi > 0.5) farthest from the domain boundary
        phi = data["phase_field_gp"][k]
        ny, nx = phi.shape
        jj, ii = np.mgrid[0:ny, 0:nx]
        depth = np.minimum.reduce([ii, nx - 1 - ii, jj, ny - 1 - jj])
        iy, ix = np.unravel_index(np.argmax(np.where(phi > 0.5, depth, -1)), phi.shape)
        rows = slice(max(iy - zoom_half_width_px, 0), iy + zoom_half_width_px)
        cols = slice(max(ix - zoom_half_width_px, 0), ix + zoom_half_width_px)
        ax = axes[k, 0]
        sc = ax.scatter(gx[rows, cols], gy[rows, cols], c=history[rows, cols], s=4, norm=norm, cmap="inferno")
        ax.set_aspect("equal")
        ax.set_title(f"increment {int(data['increment'][k])}, u = {float(data['u'][k]):.4g} mm\nH at the Gauss points near the crack tip")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        fig.colorbar(sc, ax=ax, label="H (N/mm$^2$)")
        ax = axes[k, 1]
        im = ax.imshow(history, origin="lower", extent=_extent(data), norm=norm, cmap="inferno", interpolation="nearest")
        ax.set_title(f"pixel map {history.shape[1]} x {history.shape[0]}\nh_px = {float(data['h_px']):.4g} mm")
        ax.add_patch(plt.Rectangle((gx[rows, cols].min(), gy[rows, cols].min()), np.ptp(gx[rows, cols]), np.ptp(gy[rows, cols]),
                                   fill=False, edgecolor="cyan", lw=1))
        ax.set_xlabel("x (mm)")
        fig.colorbar(im, ax=ax, label="H (N/mm$^2$)")
    _save(fig, path)


def training_figure(data: dict, model, loss, path) -> None:
    """Loss per epoch, then per training increment: FEM phi, PICNN phi (no smoothing), |error|."""
    n = len(data["increment"])
    fig = plt.figure(figsize=(13, 3.2 + 3.8 * n))
    grid = fig.add_gridspec(n + 1, 3, height_ratios=[0.8] + [1.0] * n)
    ax = fig.add_subplot(grid[0, :])
    for stage, part in loss.groupby("stage", sort=False):
        ax.semilogy(part["epoch"], part["loss"], lw=0.8, label=f"{stage}")
    ax.set_xlabel("epoch")
    ax.set_ylabel("physics loss ||R||$_2$")
    ax.set_title(f"training: {len(loss)} epochs, {float(loss['wall_s'].iloc[-1]):.0f} s")
    ax.legend()
    ax.grid(alpha=0.3)
    for k in range(n):
        reference = data["phase_field_gp"][k]
        predicted = model.predict(data["history"][k])
        error = np.abs(predicted - reference)
        panels = [(reference, "FEM phi (Gauss points)", "viridis", (0, 1)),
                  (predicted, "PICNN phi (no smoothing)", "viridis", (0, 1)),
                  (error, f"|error|: mean {error.mean():.4f}, max {error.max():.3f}", "magma", (0, max(error.max(), 1e-6)))]
        for col, (image, title, cmap, (lo, hi)) in enumerate(panels):
            ax = fig.add_subplot(grid[k + 1, col])
            im = ax.imshow(image, origin="lower", extent=_extent(data), cmap=cmap, vmin=lo, vmax=hi)
            ax.set_title(f"inc {int(data['increment'][k])}: {title}", fontsize=9)
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    _save(fig, path)
