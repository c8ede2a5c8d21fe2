"""The paper's figures: meshes, force-displacement curves, the training data and loss, FEM against
IFENN contours and 3D views, the mesh study and the phase-field step's time."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ifenn import geometry  # noqa: E402
from ifenn.fem import supports  # noqa: E402
from ifenn.run_files import read_phase_field_maps  # noqa: E402
from ifenn.studies.figures.common import extent, gauss_point_coordinates, save, window  # noqa: E402


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
    outward = {"left": (-1, 0), "right": (1, 0), "bottom": (0, -1), "top": (0, 1)}
    for condition in supports.conditions(scene):
        (ax_, ay), (bx, by) = condition.start, condition.end
        nx_, ny_ = outward.get(condition.edge, (0, -1) if condition.kind == "fixed" else (0, 1))
        component = "xy"[condition.component]
        if condition.kind == "fixed":
            if condition.is_point:
                ax.plot([ax_], [ay], marker="^", ms=9, color="tab:blue", alpha=0.7)
            else:
                ax.plot([ax_, bx], [ay, by], color="tab:blue", lw=5, alpha=0.5)
            shift = 0.06 + 0.04 * condition.component
            ax.text((ax_ + bx) / 2 + nx_ * shift * span, (ay + by) / 2 + ny_ * shift * span,
                    f"u{component} = 0", ha="center", va="center", color="tab:blue", fontsize=8)
        else:
            sign = -1.0 if condition.kind == "-load" else 1.0
            dx, dy = (sign * 0.06 * span, 0) if component == "x" else (0, sign * 0.06 * span)
            for t in (np.linspace(0.1, 0.9, 5) if not condition.is_point else [0.0]):
                px, py = ax_ + t * (bx - ax_), ay + t * (by - ay)
                ax.annotate("", xy=(px + dx, py + dy), xytext=(px, py), arrowprops={"arrowstyle": "->", "color": "tab:green"})
            ax.text((ax_ + bx) / 2 + nx_ * 0.12 * span, (ay + by) / 2 + ny_ * 0.12 * span,
                    f"u{component} = {'-' if sign < 0 else ''}u",
                    ha="center", va="center", color="tab:green", fontsize=8)
    for a, b, c, d in geometry.cutouts(scene):
        ax.fill([a, b, b, a], [c, c, d, d], facecolor="white", edgecolor="k", hatch="//", lw=1, zorder=5,
                label="cut-out")
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
    save(fig, path)


def force_displacement_figure(curves: dict, path, title: str = "", u_max: float | None = None, force_unit: str = "N/mm") -> None:
    """Reaction force against prescribed displacement; ``curves`` maps label -> DataFrame
    with columns u and reaction_force; ``force_unit``: N for a scene with a thickness."""
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for label, frame in curves.items():
        frame = frame if u_max is None else frame[frame["u"] <= u_max + 1e-15]
        ax.plot(frame["u"], frame["reaction_force"], label=label, lw=1.4)
    ax.set_xlabel("prescribed displacement u (mm)")
    ax.set_ylabel(f"reaction force ({force_unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    save(fig, path)


def training_data_figure(data: dict, path, zoom_half_width_px: int = 40) -> None:
    """H at the Gauss points (scatter, zoomed on the crack tip) beside the pixel map (whole
    image), one row per training increment; log colour scale shared per row."""
    from matplotlib.colors import LogNorm

    gx, gy = gauss_point_coordinates(data)
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
        im = ax.imshow(history, origin="lower", extent=extent(data), norm=norm, cmap="inferno", interpolation="nearest")
        ax.set_title(f"pixel map {history.shape[1]} x {history.shape[0]}\nh_px = {float(data['h_px']):.4g} mm")
        ax.add_patch(plt.Rectangle((gx[rows, cols].min(), gy[rows, cols].min()), np.ptp(gx[rows, cols]), np.ptp(gy[rows, cols]),
                                   fill=False, edgecolor="cyan", lw=1))
        ax.set_xlabel("x (mm)")
        fig.colorbar(im, ax=ax, label="H (N/mm$^2$)")
    save(fig, path)


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
            im = ax.imshow(image, origin="lower", extent=extent(data), cmap=cmap, vmin=lo, vmax=hi)
            ax.set_title(f"inc {int(data['increment'][k])}: {title}", fontsize=9)
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    save(fig, path)


def comparison_levels(fem_maps: dict, ifenn_maps: dict, switch: int, count: int) -> list[int]:
    """``count`` saved increments common to both runs, evenly spread from the switch-over on."""
    common = sorted(i for i in set(fem_maps) & set(ifenn_maps) if i >= switch)
    if not common:
        return []
    return sorted({common[int(round(k))] for k in np.linspace(0, len(common) - 1, count)})


def comparison_figure(fem_history, ifenn_history, fem_fields, ifenn_fields, path, title: str,
                      levels: int = 4, zoom: dict | None = None, verified_history=None, verified_fields=None) -> None:
    """Force curves of FEM and IFENN, then phase-field contours at ``levels`` load levels after
    the switch-over: FEM (top row), IFENN as published, and verified IFENN when given (its
    history and fields), same colour scale."""
    fem_maps, attrs = read_phase_field_maps(fem_fields)
    ifenn_maps, _ = read_phase_field_maps(ifenn_fields)
    panels = [("FEM", fem_maps), ("IFENN", ifenn_maps)]
    if verified_fields is not None:
        verified_maps, _ = read_phase_field_maps(verified_fields)
        panels.append(("verified IFENN", verified_maps))
        common = {k: v for k, v in ifenn_maps.items() if k in verified_maps}
    else:
        common = ifenn_maps
    switch = int(ifenn_history.increment[ifenn_history.hybrid_active == 1].min())
    chosen = comparison_levels(fem_maps, common, switch, levels)
    rows, cols, extent = window(attrs, zoom)
    ncol = max(len(chosen), 1)
    aspect = (extent[3] - extent[2]) / (extent[1] - extent[0])
    n_maps = len(panels)
    fig = plt.figure(figsize=(3.2 * ncol + 1, 3.6 + n_maps * 3.2 * aspect + 0.6))
    grid = fig.add_gridspec(1 + n_maps, ncol, height_ratios=[1.3] + [aspect * 1.1] * n_maps, hspace=0.5)
    ax = fig.add_subplot(grid[0, :])
    ax.plot(fem_history.u, fem_history.reaction_force, label="FEM", lw=1.6)
    ax.plot(ifenn_history.u, ifenn_history.reaction_force, "--", label="IFENN (published)", lw=1.6)
    if verified_history is not None:
        ax.plot(verified_history.u, verified_history.reaction_force, "-.", label="verified IFENN", lw=1.6)
    ax.axvline(ifenn_history.u[ifenn_history.increment == switch].iloc[0], color="0.5", lw=0.8, ls=":", label="switch-over")
    for k, increment in enumerate(chosen):
        ax.axvline(fem_maps[increment][0], color="0.8", lw=0.6)
        ax.text(fem_maps[increment][0], ax.get_ylim()[1] * 0.95, str(k + 1), ha="center", fontsize=8)
    ax.set_xlabel("u (mm)")
    ax.set_ylabel("reaction force (N/mm)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    image = None
    for k, increment in enumerate(chosen):
        for r, (label, maps) in enumerate(panels):
            ax = fig.add_subplot(grid[r + 1, k])
            image = ax.imshow(maps[increment][1][rows, cols], origin="lower", extent=extent, cmap="jet", vmin=0, vmax=1)
            ax.set_title(f"{k + 1}: {label}, u = {maps[increment][0]:.4g}", fontsize=8)
            ax.tick_params(labelsize=7)
    if image is not None:
        fig.colorbar(image, ax=fig.axes[1:], shrink=0.8, label="phi (Gauss points)")
    save(fig, path)


def views_3d_figure(fem_fields, ifenn_fields, increment: int, views: list, path, zoom: dict | None = None) -> None:
    """phi at the Gauss points of one increment as 3D surfaces, FEM (top) and IFENN (bottom),
    seen from each (azimuth, elevation) pair in ``views`` (degrees)."""
    fem_maps, attrs = read_phase_field_maps(fem_fields)
    ifenn_maps, _ = read_phase_field_maps(ifenn_fields)
    rows, cols, extent = window(attrs, zoom)
    h = float(attrs["h_px"])
    fig = plt.figure(figsize=(3.4 * len(views), 7))
    for r, (label, maps) in enumerate((("FEM", fem_maps), ("IFENN", ifenn_maps))):
        phi = maps[increment][1][rows, cols]
        x = extent[0] + (np.arange(phi.shape[1]) + 0.5) * h
        y = extent[2] + (np.arange(phi.shape[0]) + 0.5) * h
        X, Y = np.meshgrid(x, y)
        for c, (azimuth, elevation) in enumerate(views):
            ax = fig.add_subplot(2, len(views), r * len(views) + c + 1, projection="3d")
            ax.plot_surface(X, Y, phi, cmap="jet", vmin=0, vmax=1, linewidth=0, antialiased=False, rcount=120, ccount=120)
            ax.view_init(elev=elevation, azim=azimuth)
            ax.set_zlim(0, 1)
            ax.set_title(f"{label}: az {azimuth}, el {elevation}", fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle(f"phi at the Gauss points, increment {increment} (u = {fem_maps[increment][0]:.4g} mm)")
    save(fig, path)


def mesh_study_figure(cases: list[dict], path, u_max: float, zoom: dict | None = None) -> None:
    """Force curves of FEM and IFENN for several meshes (cut at u_max), and zoomed phase-field
    contours of each at the last saved increment with u <= u_max. ``cases``: dicts with keys
    label, fem_history, ifenn_history, fem_fields, ifenn_fields."""
    fig = plt.figure(figsize=(4 * len(cases), 9))
    grid = fig.add_gridspec(3, len(cases), height_ratios=[1.4, 1, 1])
    ax = fig.add_subplot(grid[0, :])
    for k, case in enumerate(cases):
        color = f"C{k}"
        for frame, style, method in ((case["fem_history"], "-", "FEM"), (case["ifenn_history"], "--", "IFENN")):
            frame = frame[frame.u <= u_max + 1e-15]
            ax.plot(frame.u, frame.reaction_force, style, color=color, label=f"{case['label']} {method}", lw=1.3)
    ax.set_xlabel("u (mm)")
    ax.set_ylabel("reaction force (N/mm)")
    ax.legend(fontsize=7, ncol=len(cases))
    ax.grid(alpha=0.3)
    for k, case in enumerate(cases):
        fem_maps, attrs = read_phase_field_maps(case["fem_fields"])
        ifenn_maps, _ = read_phase_field_maps(case["ifenn_fields"])
        common = [i for i in set(fem_maps) & set(ifenn_maps) if fem_maps[i][0] <= u_max + 1e-15]
        if not common:
            continue
        increment = max(common)
        rows, cols, extent = window(attrs, zoom)
        for r, (label, maps) in enumerate((("FEM", fem_maps), ("IFENN", ifenn_maps))):
            ax = fig.add_subplot(grid[r + 1, k])
            image = ax.imshow(maps[increment][1][rows, cols], origin="lower", extent=extent, cmap="jet", vmin=0, vmax=1)
            ax.set_title(f"{case['label']} {label}, u = {maps[increment][0]:.4g}", fontsize=8)
            ax.tick_params(labelsize=7)
    fig.colorbar(image, ax=fig.axes[1:], shrink=0.8, label="phi")
    save(fig, path)


def phase_field_time_figure(timing, cases: list[dict], path) -> None:
    """Phase-field time per increment (left) and cumulative over the propagation stage
    (right) against lc/h, FEM and IFENN. ``timing``: the timing table; ``cases``: dicts with
    run and lc_over_h."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for method, marker in (("fem", "o-"), ("ifenn", "s--")):
        xs, per_inc, cumulative = [], [], []
        for case in cases:
            row = timing[(timing.run == case["run"]) & (timing.method == method)]
            if len(row):
                xs.append(case["lc_over_h"])
                per_inc.append(float(row.t_phase_field_s.iloc[0]))
                cumulative.append(float(row.phase_field_cumulative_s.iloc[0]))
        left.plot(xs, per_inc, marker, label=method.upper())
        right.plot(xs, cumulative, marker, label=method.upper())
    left.set_ylabel("phase-field step per increment (s)")
    right.set_ylabel("phase-field time, propagation stage (s)")
    for ax in (left, right):
        ax.set_xlabel("lc / h")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle("phase-field cost on this machine's CPU (one core): IFENN = pixels + inference + smoothing + back-projection")
    save(fig, path)
