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
