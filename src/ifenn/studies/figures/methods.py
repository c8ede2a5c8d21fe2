"""The figures of what the workflow measures beyond the paper: the stability map, speed against
accuracy, the error's sources, the whole path, the whole run's speed, the finer references, the
adaptive mesh, what a network is worth, and a specimen against its source."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ifenn.studies.figures.common import save  # noqa: E402

STABILITY_COLOURS = {"ok": "#4daf4a", "peak off": "#ffd92f", "crack path wrong": "#ff7f00",
                     "no load drop": "#e41a1c", "diverged": "#6a3d9a"}


def stability_map_figure(table, path) -> None:
    """One panel per swept quantity (load step, lc/h, IFENN option): a coloured cell per
    value and method with its label, the force error against the reference and the wall time."""
    panels = list(dict.fromkeys(table.panel))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), squeeze=False,
                             gridspec_kw={"width_ratios": [max(len(set(table[table.panel == p].value)), 1) for p in panels]})
    for ax, panel in zip(axes[0], panels, strict=True):
        rows = table[table.panel == panel]
        values, methods = list(dict.fromkeys(rows.value)), ["fem", "ifenn"]
        for _, row in rows.iterrows():
            x, y = values.index(row.value), methods.index(row.method)
            ax.add_patch(plt.Rectangle((x - 0.48, y - 0.45), 0.96, 0.9, color=STABILITY_COLOURS[row.label]))
            error = row.get("force_l2_rel_error", np.nan)
            text = row.label + (f"\nL2 {100 * error:.1f}%" if np.isfinite(error) else "")
            if np.isfinite(row.get("wall_s", np.nan)):
                text += f"\n{row.wall_s:.0f} s"
            ax.text(x, y, text, ha="center", va="center", fontsize=7)
        ax.set_xlim(-0.5, len(values) - 0.5)
        shown = [m for m in methods if (rows.method == m).any()]
        ax.set_ylim(methods.index(shown[0]) - 0.5, methods.index(shown[-1]) + 0.5)
        ax.set_xticks(range(len(values)), values, rotation=30 if panel == "IFENN option" else 0, fontsize=8,
                      ha="right" if panel == "IFENN option" else "center")
        ax.set_yticks([methods.index(m) for m in shown], [m.upper() for m in shown])
        ax.set_title(panel)
        ax.set_aspect("auto")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in STABILITY_COLOURS.values()]
    fig.legend(handles, list(STABILITY_COLOURS), loc="upper center", ncol=5, fontsize=8, frameon=False, bbox_to_anchor=(0.5, -0.1))
    fig.suptitle("Stability map: label of each cell (force-curve L2 error vs its reference, wall time)")
    save(fig, path)


def _label_column(ax, points: list[tuple[float, float, str, bool]], spacing: float = 0.045) -> None:
    """Name ``points`` ((x, y, name, bold) in data coordinates) in a column right of ``ax``, each
    at its point's height where it can be and moved apart where names would overlap, with a thin
    line to its point."""
    to_axes = ax.transAxes.inverted()
    wanted = sorted(((float(to_axes.transform(ax.transData.transform((x, y)))[1]), x, y, name, bold)
                     for x, y, name, bold in points), reverse=True)
    heights, top = [], 1.0
    for h, *_ in wanted:   # top down, no closer than spacing; the column shifted up whole if it ran below the axes
        top = min(h, top - spacing if heights else 1.0)
        heights.append(top)
    overrun = min(0.0, heights[-1]) if heights else 0.0
    heights = [h - overrun for h in heights]
    for height, (_, x, y, name, bold) in zip(heights, wanted, strict=True):
        ax.annotate(name, (x, y), xytext=(1.02, height), textcoords="axes fraction", fontsize=8, va="center",
                    fontweight="bold" if bold else "normal", annotation_clip=False,
                    arrowprops={"arrowstyle": "-", "color": "grey", "lw": 0.4, "alpha": 0.7, "shrinkA": 0, "shrinkB": 4})


def speed_accuracy_figure(table, scene: str, path, benchmark=None) -> None:
    """One scene's speed against accuracy: the force curve's L2 error (left) and the error in the work
    of the load (right; the dissipated energy once the specimen is cut, which does not hinge on where
    the drop falls) against the whole run's wall, log-log. One marker per method family (FEM circles,
    IFENN squares, whole-path IFENN diamonds, adaptive-mesh runs triangles; hollow: converged
    staggering; colour: the load schedule), each panel's Pareto front a step line through the
    black-outlined points. Named: the front's runs, the reference (drawn at the bottom edge), the
    baseline (ringed: FEM as published) and the combined runs (starred); every point with its numbers
    is a row of speed_accuracy.csv. ``benchmark`` (the phase_field_speed table) adds its same-core
    ratio of the IFENN phase-field step to FEM's under the panels."""
    import textwrap

    from ifenn.studies.tables.speed_accuracy import PARETO

    rows = table[table.scene == scene].reset_index(drop=True)
    schedules = list(dict.fromkeys(table.schedule))   # the same colour for a schedule in every scene's figure
    colours = dict(zip(schedules, plt.cm.tab10(np.arange(len(schedules)) % 10), strict=True))
    fig, axes = plt.subplots(2, 1, figsize=(8.5, 11), gridspec_kw={"hspace": 0.3})   # a page's width: stacked
    panels = {"pareto_wall_s": "force curve: L2 error (%)", "pareto_work_wall_s": "work of the load: |error| (%)"}
    for ax, (pareto, column, error_column) in zip(axes, [p for p in PARETO if p[0] in panels], strict=True):
        errors = rows[error_column][~rows.is_reference]
        floor = 0.5 * errors[errors > 0].min() if (errors > 0).any() else 1e-6
        labels = []
        for _, r in rows.iterrows():
            x, y = r[column], 100 * (floor if r.is_reference else max(floor, r[error_column]))
            colour = colours[r.schedule]
            marker = {"fem": "o", "adaptive": "^"}.get(r.method, "D" if r.variant.endswith("whole path") else "s")
            ax.scatter(x, y, marker=marker, s=50, facecolor="white" if r.converged else colour,
                       edgecolor="k" if r[pareto] else colour, linewidth=1.6, zorder=3)
            if r.role == "baseline":
                ax.scatter(x, y, marker="o", s=320, facecolor="none", edgecolor="tab:red", linewidth=1.5, zorder=2)
            elif r.role == "combined":
                ax.scatter(x, y, marker="*", s=380, facecolor="none", edgecolor="tab:green", linewidth=1.2, zorder=2)
            if r.role or r[pareto]:
                labels.append((x, y, r.run + {"reference": " (reference)", "baseline": " (FEM as published)"}.get(r.role, ""),
                               bool(r.role)))
        front = rows[rows[pareto]].sort_values(column)
        ax.step(front[column], 100 * np.maximum(front[error_column], floor), where="post", color="k", lw=1, alpha=0.6)
        ax.set_xscale("log")
        ax.set_yscale("log")
        _label_column(ax, labels)
        ax.set_xlabel("wall time of the whole run (s, sum of its increments)", fontsize=9)
        ax.set_ylabel(panels[pareto], fontsize=9)
        ax.set_title(panels[pareto].split(":")[0] + f" against {rows.reference.iloc[0]}", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    handles = [plt.Line2D([], [], marker="o", ls="", color="grey", label="FEM"),
               plt.Line2D([], [], marker="s", ls="", color="grey", label="IFENN"),
               plt.Line2D([], [], marker="D", ls="", color="grey", label="IFENN, whole path"),
               plt.Line2D([], [], marker="^", ls="", color="grey", label="adaptive mesh"),
               plt.Line2D([], [], marker="o", ls="", mfc="white", mec="grey", label="converged staggering (hollow)"),
               plt.Line2D([], [], color="k", label="Pareto front (black outline)"),
               plt.Line2D([], [], marker="o", ls="", mfc="none", mec="tab:red", ms=13, label="FEM as published"),
               plt.Line2D([], [], marker="*", ls="", mfc="none", mec="tab:green", ms=15, label="combined run")]
    handles += [plt.Line2D([], [], marker="o", ls="", color=c, label=f"schedule {v}") for v, c in colours.items()
                if v in set(rows.schedule)]
    fig.legend(handles=handles, fontsize=8, loc="lower center", ncol=4, frameon=False, bbox_to_anchor=(0.5, 0.045))
    note = "Wall times on a CPU, one thread a run, two runs at a time on a 2-core machine."
    if benchmark is not None and len(benchmark):
        names = {"ifenn_full_convolution": "the published network step (full image, convolutions)", "ifenn_full": "full image, orbit",
                 "ifenn_process_zone": "process zone"}
        ratios = [f"{label}{'' if device == 'cpu' else f' on {device}'} {g.min():.2g}-{g.max():.2g}x"
                  for device in dict.fromkeys(benchmark.device) for method, label in names.items()
                  if len(g := benchmark[(benchmark.method == method) & (benchmark.device == device)].phase_field_speedup_vs_fem)]
        note += (" The phase-field step against the FEM step it replaces, same core (phase_field_speed.csv; >1 faster): "
                 + ", ".join(ratios) + ".")
    fig.text(0.5, 0.005, "\n".join(textwrap.wrap(note, 120)), ha="center", va="bottom", fontsize=8)
    fig.suptitle(f"{scene}: speed against accuracy", fontsize=12)
    fig.subplots_adjust(left=0.1, right=0.66, top=0.94, bottom=0.17)
    save(fig, path)


ERROR_SOURCE_LABELS = {"pixel": "pixel equation vs Q1 FEM", "cap": "H cap", "network": "network vs exact pixel solve",
                       "smoothing": "Gaussian smoothing", "irreversibility": "max with FEM phi at switch-over",
                       "published_step": "published step (sum of the above)", "staggering": "single pass vs converged (FEM)"}


ERROR_SOURCE_COLOURS = {"pixel": "tab:grey", "cap": "tab:purple", "network": "tab:red", "smoothing": "tab:blue",
                        "irreversibility": "tab:orange", "published_step": "k", "staggering": "tab:green"}


def error_sources_figure(sources, path) -> None:
    """Per run (rows): each source's force error over the FEM peak (left: the signed mean over the
    replayed states as bars, additive, so the parts sum to the published step; the RMS as diamonds;
    %) and the largest |phi difference| between the two variants it compares (right).
    ``sources``: the table of ifenn.studies.drivers.error_sources.error_sources."""
    runs = list(dict.fromkeys(sources.run))
    fig, axes = plt.subplots(len(runs), 2, figsize=(12, 3.4 * len(runs) + 0.8), squeeze=False,
                             gridspec_kw={"width_ratios": [2, 1]})
    for (left, right), run in zip(axes, runs, strict=True):
        rows = sources[sources.run == run].set_index("source")
        names = [s for s in ERROR_SOURCE_LABELS if s in rows.index]
        y = np.arange(len(names))[::-1]
        colours = [ERROR_SOURCE_COLOURS[s] for s in names]
        mean, rms = 100 * rows.loc[names, "force_mean"].to_numpy(), 100 * rows.loc[names, "force_rms"].to_numpy()
        left.barh(y, mean, color=colours, alpha=0.8, label="signed mean over states")
        left.scatter(rms, y, marker="D", s=28, facecolor="white", edgecolor="k", zorder=3, label="RMS over states")
        for yy, m, r in zip(y, mean, rms, strict=True):
            left.annotate(f"{m:+.1f} (RMS {r:.1f})", (max(m, r, 0.0), yy), xytext=(6, 0), textcoords="offset points",
                          va="center", fontsize=7)
        left.axvline(0, color="k", lw=0.6)
        left.set_yticks(y, [ERROR_SOURCE_LABELS[s] for s in names], fontsize=8)
        left.set_xlabel("force difference / FEM peak (%)")
        lo, hi = min(mean.min(), 0.0), max(mean.max(), rms.max(), 0.0)
        left.set_xlim(lo - 0.05 * (hi - lo + 1e-9), hi + 0.35 * (hi - lo + 1e-9))
        first = rows.iloc[0]
        left.set_title(f"{run}: {int(first.states)} FEM states after the switch-over replayed. Whole published run: "
                       f"post-switch RMS error {100 * first.postswitch_rms_error:.1f} %,\nfinal force "
                       f"{100 * first.final_force_ifenn:.1f} % of the FEM peak (FEM {100 * first.final_force_fem:.1f} %)",
                       fontsize=8, loc="left")
        left.legend(fontsize=7, loc="lower right")
        right.barh(y, rows.loc[names, "phi_max_abs"], color=colours, alpha=0.8)
        right.set_yticks(y, [])
        right.set_xlabel("largest |phi difference| (pixels, all states)")
        right.set_title("phase field", fontsize=8)
        for ax in (left, right):
            ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle("Where IFENN's post-switch error comes from, replayed on the same FEM states: pixel equation, H cap, "
                 "network, smoothing,\nirreversibility (together: the published step) and single-pass staggering",
                 fontsize=10)
    fig.tight_layout()
    save(fig, path)


def whole_path_figure(pairs: dict, table, path) -> None:
    """IFENN over the whole load path against FEM. Per run (columns): the force curves
    of FEM and the whole-path run with FEM's peak and phi-threshold increment marked (top), and the
    verified step's work per increment (whole-image CG iterations, and the share of the image
    corrected) against u (bottom). ``pairs``: run -> (FEM history, IFENN history) DataFrames;
    ``table``: ifenn.studies.drivers.whole_path.whole_path_table (the numbers in the titles)."""
    runs = list(pairs)
    fig, axes = plt.subplots(2, len(runs), figsize=(3.6 * len(runs) + 0.6, 6.4), squeeze=False, sharex="col")
    rows = table.set_index("run")
    for k, run in enumerate(runs):
        fem, ifenn = pairs[run]
        top, bottom = axes[0, k], axes[1, k]
        top.plot(fem.u, fem.reaction_force.abs(), color="k", lw=1.2, label="FEM")
        top.plot(ifenn.u, ifenn.reaction_force.abs(), color="tab:red", lw=1.0, ls="--", label="IFENN, whole path")
        r = rows.loc[run]
        top.axvline(r.u_peak_fem, color="0.6", lw=0.6)
        if np.isfinite(r.u_fem_switch):
            top.axvline(r.u_fem_switch, color="tab:blue", lw=0.6, ls=":", label="FEM phi_max > threshold")
        top.set_title(f"{run}\npeak {100 * r.peak_force_rel_error:+.2f} %, u_peak {100 * r.u_peak_rel_error:+.1f} %,\n"
                      f"post-peak RMS {100 * r.post_peak_rms_error:.2f} %, final {100 * r.final_force_fraction_ifenn:.1f} "
                      f"({100 * r.final_force_fraction_fem:.1f}) %", fontsize=7)
        top.set_ylabel("reaction force (N/mm)" if k == 0 else "")
        if "verify_solve_work" in ifenn:
            bottom.plot(ifenn.u, ifenn.verify_solve_work, color="tab:red", lw=1.0, label="correction, whole-image CG its")
            twin = bottom.twinx()
            twin.plot(ifenn.u, ifenn.verify_corrected_fraction, color="tab:green", lw=0.8, label="share corrected")
            twin.set_ylim(0, 1.05)
            if k == len(runs) - 1:
                twin.set_ylabel("share of the image corrected", color="tab:green")
        bottom.set_xlabel("u (mm)")
        bottom.set_ylabel("whole-image CG iterations" if k == 0 else "")
        bottom.set_yscale("symlog", linthresh=1.0)
        bottom.set_ylim(bottom=0)
        if k == 0:
            top.legend(fontsize=6)
            bottom.legend(fontsize=6, loc="upper left")
    fig.suptitle("Verified IFENN from the first increment against FEM (same scene, same schedule)", fontsize=9)
    fig.tight_layout()
    save(fig, path)


def whole_run_speed_figure(increments, summary, path) -> None:
    """The phase-field step over the whole run, FEM against whole-path IFENN, one process
    (ifenn.studies.drivers.whole_run_benchmark). Per run (columns): seconds per phase-field step against u
    (top, log), and the cumulative phase-field time (bottom), FEM's phi-threshold u marked. IFENN
    is drawn once per device it ran on (column ``device``, labelled by name)."""
    runs = list(dict.fromkeys(increments.run))
    fig, axes = plt.subplots(2, len(runs), figsize=(4.2 * len(runs), 6.4), squeeze=False, sharex="col")
    ifenn_colours = ["tab:red", "tab:green", "tab:purple"]
    rows = summary.set_index(["run", "method", "device"])
    series = list(dict.fromkeys(zip(increments.method, increments.device, strict=True)))
    series = [key for key in series if key[0] == "fem"] + [key for key in series if key[0] != "fem"]
    for k, run in enumerate(runs):
        for index, (method, device) in enumerate(series):
            frame = increments[(increments.run == run) & (increments.method == method) & (increments.device == device)]
            if frame.empty:
                continue
            colour = "k" if method == "fem" else ifenn_colours[(index - 1) % len(ifenn_colours)]
            label = "FEM (Q1 solve, PETSc, CPU)" if method == "fem" else f"IFENN, whole path (verified), network on {device}"
            axes[0, k].plot(frame.u, frame.t_phase_field_s, color=colour, lw=0.6, alpha=0.8, label=label)
            axes[1, k].plot(frame.u, frame.t_phase_field_s.cumsum(), color=colour, lw=1.2, label=label)
        fem = increments[(increments.run == run) & (increments.method == "fem")]
        fem_row = rows.loc[run, "fem"].iloc[0]
        switch = int(fem_row.fem_switch_increment)
        if switch <= len(fem):
            u_switch = float(fem.u[fem.increment == switch].iloc[0])
            for ax in axes[:, k]:
                ax.axvline(u_switch, color="tab:blue", lw=0.6, ls=":")
        speedups = ", ".join(f"{row.phase_field_speedup_vs_fem:.2f}x ({device})" for device, row in rows.loc[run, "ifenn"].iterrows())
        axes[0, k].set_title(f"{run} ({fem_row.elements} elements)\n"
                             f"FEM / IFENN phase-field time over the run: {speedups}", fontsize=8)
        axes[0, k].set_yscale("log")
        axes[0, k].set_ylabel("phase-field step (s)" if k == 0 else "")
        axes[1, k].set_ylabel("cumulative phase-field time (s)" if k == 0 else "")
        axes[1, k].set_xlabel("u (mm)")
        axes[0, k].grid(True, which="both", alpha=0.3)
        axes[1, k].grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Phase-field step over the whole run, same process, increments interleaved "
                 "(dotted: FEM's phi_max > switch threshold)", fontsize=9)
    fig.tight_layout()
    save(fig, path)


def reference_convergence_figure(curves: dict, table, path) -> None:
    """Per case (columns): the force curves after the peak of FEM at h, FEM on the finer mesh and
    the IFENN runs (top), and each curve's |F| - |F| of the finer FEM over the peak of FEM at h
    (bottom). ``curves``: case -> {label: history} (FEM at h first, the finer FEM second);
    ``table``: ifenn.studies.tables.reference_convergence.reference_convergence_table."""
    cases = list(curves)
    fig, axes = plt.subplots(2, len(cases), figsize=(4.4 * len(cases) + 0.6, 6.4), squeeze=False, sharex="col")
    for k, case in enumerate(cases):
        rows = table[table.case == case]
        first = rows.iloc[0]
        peak, window = first.peak_force_fem, (first.u_peak_fem, None)
        labels = list(curves[case])
        fine = curves[case][labels[1]]
        u_fine, f_fine = fine.u.to_numpy(), fine.reaction_force.abs().to_numpy()
        top, bottom = axes[0, k], axes[1, k]
        styles = [dict(color="k", lw=1.4), dict(color="k", lw=1.0, ls=":")]
        colours = iter(["tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:brown"])
        numbers = rows.set_index("run")  # FEM at h: run ""
        for j, label in enumerate(labels):
            history = curves[case][label]
            u, force = history.u.to_numpy(), history.reaction_force.abs().to_numpy()
            style = styles[j] if j < 2 else dict(color=next(colours), lw=1.0, ls="--")
            run = label.split(" ", 1)[1] if j >= 2 else ""
            if j != 1:
                r = numbers.loc[run]
                label = f"{label}: RMS {100 * r.rms_vs_fem:.2f} % vs FEM, {100 * r.rms_vs_fine:.2f} % vs finer"
            after = u >= window[0] * 0.97
            top.plot(u[after], force[after], label=label, **style)
            if j != 1:
                inside = u > window[0]
                bottom.plot(u[inside], 100 * (force[inside] - np.interp(u[inside], u_fine, f_fine)) / peak, **style)
        top.set_title(f"{case}: after the peak of FEM {first.fem_run}", fontsize=8)
        top.set_ylabel("reaction force (N/mm)" if k == 0 else "")
        top.legend(fontsize=6)
        bottom.axhline(0.0, color="0.6", lw=0.6)
        bottom.set_xlabel("u (mm)")
        bottom.set_ylabel("|F| - |F| finer FEM (% of the FEM peak)" if k == 0 else "")
    fig.suptitle("Which discretisation is right after the peak: IFENN and its FEM reference against a finer FEM", fontsize=9)
    fig.tight_layout()
    save(fig, path)


def adaptive_resolution_figure(curves: dict, table, path) -> None:
    """Per case (columns): the force curves of FEM at h, the finer reference (uniform FEM or its
    adaptive run) and the adaptive runs (top); each curve's |F| - |F| of the reference over its peak
    (middle); the displacement dofs of every run on an adaptive mesh, the reference's included, over
    the finer uniform mesh's (bottom). ``curves``: case -> {label: history} (FEM at h first, the
    finer reference second); ``table``: ifenn.studies.tables.adaptive_resolution.adaptive_resolution_table."""
    cases = list(curves)
    fig, axes = plt.subplots(3, len(cases), figsize=(4.8 * len(cases) + 0.6, 8.4), squeeze=False, sharex="col",
                             gridspec_kw={"height_ratios": [2.2, 1.2, 1.0]})
    for k, case in enumerate(cases):
        numbers = table[table.case == case].set_index("run")
        labels = list(curves[case])
        fine = curves[case][labels[1]]
        u_fine, f_fine = fine.u.to_numpy(), fine.reaction_force.abs().to_numpy()
        peak = f_fine.max()
        top, middle, bottom = axes[0, k], axes[1, k], axes[2, k]
        colours = iter(["tab:red", "tab:blue", "tab:green", "tab:purple"])
        for j, label in enumerate(labels):
            history = curves[case][label]
            u, force = history.u.to_numpy(), history.reaction_force.abs().to_numpy()
            style = [dict(color="k", lw=1.2, ls="--"), dict(color="k", lw=1.6, ls=":")][j] if j < 2 else dict(color=next(colours), lw=1.2)
            run = label.split(" ", 1)[1]   # "FEM <run>", "adaptive <run>"
            if j != 1:
                r = numbers.loc[run]
                label = (f"{label}: peak {r.peak_error_vs_fine_pct:+.2f} %, post-peak RMS {r.post_peak_rms_vs_fine_pct:.2f} %, "
                         f"{r.wall_s:.0f} s, dofs {100 * r.dofs_fraction_of_fine:.0f} % of fine")
            top.plot(u, force, label=label, **style)
            if j != 1:
                middle.plot(u, 100 * (force - np.interp(u, u_fine, f_fine)) / peak, **style)
            if "dofs" in history:
                bottom.plot(u, 100 * history.dofs.to_numpy() / numbers.fine_uniform_dofs.iloc[0], **style)
        top.set_title(f"{case}: against {labels[1]}", fontsize=8)
        top.set_ylabel("reaction force (N/mm)" if k == 0 else "")
        top.legend(fontsize=5.5)
        middle.axhline(0.0, color="0.6", lw=0.6)
        middle.set_ylabel("|F| - |F| finer (% of its peak)" if k == 0 else "", fontsize=7)
        bottom.set_ylabel("dofs (% of the finer uniform mesh)" if k == 0 else "", fontsize=7)
        bottom.axhline(30, color="0.6", lw=0.6, ls="--")
        bottom.set_xlabel("u (mm)")
    fig.suptitle("A displacement mesh that follows the crack: accuracy against the converged reference, and its cost", fontsize=9)
    fig.tight_layout()
    save(fig, path)


def adaptive_mesh_figure(states: list[dict], tree_of, path, title: str = "") -> None:
    """The adaptive mesh over the phase field at a few saved increments: ``states`` (dicts with
    increment, u, phase_field_gp and leaf_level), ``tree_of(leaf_level)`` -> its Quadtree."""
    from matplotlib.collections import PolyCollection

    fig, axes = plt.subplots(1, len(states), figsize=(4.2 * len(states), 4.4), squeeze=False)
    for ax, state in zip(axes[0], states, strict=True):
        tree = tree_of(state["leaf_level"])
        x0, y0 = tree.origin
        ny, nx = np.shape(state["leaf_level"])   # the scene's fine grid (the tree's may be padded)
        extent = [x0, x0 + nx * tree.h_fine, y0, y0 + ny * tree.h_fine]
        ax.imshow(state["phase_field_gp"], origin="lower", extent=extent, cmap="Reds", vmin=0, vmax=1)
        corners = tree.origin + tree.h_fine * (tree.cell_origin[:, None, :] + tree.cell_size[:, None, None] * np.array([[0, 0], [1, 0], [1, 1], [0, 1]]))
        ax.add_collection(PolyCollection(corners, facecolors="none", edgecolors="0.25", linewidths=0.15))
        ax.set_title(f"increment {state['increment']}, u = {state['u']:.4g} mm: {tree.n_cells} cells", fontsize=8)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save(fig, path)


def network_worth_figure(summary, path, target: float = 1.5) -> None:
    """What a network is worth to the verified step (ifenn.studies.drivers.network_worth), one panel per run:
    the step's time per warm start against the share of the image where the predictor answers,
    with the step without a network and the target (``target`` x faster) as lines. The oracles
    answer exactly and for free: no network asked on a zone can do better than its oracle there."""
    runs = list(dict.fromkeys(summary.run))
    fig, axes = plt.subplots(1, len(runs), figsize=(4.6 * len(runs), 4.0), squeeze=False)
    markers = {"no network": "s", "paper's network": "o", "paper's network, whole image": "D", "extrapolation": "^"}
    for ax, run in zip(axes[0], runs, strict=True):
        rows = summary[summary.run == run]
        base = float(rows[rows.variant == "no network"].t_step_s.iloc[0]) * 1e3
        ax.axhline(base, color="0.3", lw=1, label="no network")
        ax.axhline(base / target, color="tab:red", lw=1, ls="--", label=f"target: {target:g}x faster")
        oracles = rows[rows.variant.str.startswith("oracle")]
        ax.plot(oracles.evaluated_fraction, oracles.t_step_s * 1e3, "k:", marker="*", ms=10, label="oracle (exact, free) on a zone")
        for _, row in rows[~rows.variant.str.startswith("oracle")].iterrows():
            ax.plot(row.evaluated_fraction, row.t_step_s * 1e3, markers.get(row.variant, "x"), ms=8,
                    label=f"{row.variant} ({row.cg_iterations:.2f} CG it.)")
        ax.set_xscale("symlog", linthresh=1e-3)
        ax.set_xlim(-1e-4, 1.5)
        ax.set_ylim(bottom=0)
        ax.set_xlabel("share of the image the predictor answers")
        ax.set_ylabel("verified step, ms (median)")
        ax.set_title(f"{run}, {int(rows.pixels.iloc[0]):,} pixels", fontsize=9)
        ax.legend(fontsize=6.5, loc="upper left")
    fig.suptitle("What a network is worth to the verified step (one core; same certificate for every warm start)", fontsize=10)
    save(fig, path)


def specimen_figure(curves: dict, measured, measured_label: str, phi_maps: dict, attrs: dict, scene: dict,
                    path, title: str = "", band=None, band_label: str = "") -> None:
    """A specimen against its measurement: left, the force of each run (``curves``: label ->
    history frame, forces in the scene's units) over the measured curve (``measured``: columns
    displacement_mm and the force) and, shaded, its scatter ``band`` (displacement_mm, the lower and
    the upper edge's force); right, phi of the first run at three load levels (``phi_maps``:
    increment -> (u, image), ``attrs``: the pixel grid), the scene's cut-outs blanked."""
    from ifenn import geometry
    from ifenn.pixels import PixelGrid

    unit = "N" if "thickness" in scene else "N/mm"
    fig = plt.figure(figsize=(15, 4.2))
    grid = fig.add_gridspec(1, 4, width_ratios=[1.4, 1, 1, 1])
    ax = fig.add_subplot(grid[0])
    force = [c for c in measured.columns if c != "displacement_mm"][0]
    if band is not None:
        ax.fill_between(band.iloc[:, 0], band.iloc[:, 1], band.iloc[:, 2], color="0.85", label=band_label, zorder=0)
    ax.plot(measured["displacement_mm"], measured[force], "k.", ms=4, label=measured_label)
    for label, frame in curves.items():
        ax.plot(frame["u"], frame["reaction_force"], lw=1.4, label=label)
    ax.set_xlabel("displacement of the load (mm)")
    ax.set_ylabel(f"force ({unit})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    increments = sorted(phi_maps)
    if increments:
        pixel_grid = PixelGrid(float(attrs["x0"]), float(attrs["y0"]), float(attrs["h_px"]), int(attrs["nx_px"]), int(attrs["ny_px"]))
        solid = geometry.solid_pixels(scene, pixel_grid)
        (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
        picks = [increments[len(increments) // 3], increments[2 * len(increments) // 3], increments[-1]]
        for k, increment in enumerate(picks):
            u, phi = phi_maps[increment]
            axis = fig.add_subplot(grid[k + 1])
            image = axis.imshow(np.where(solid, phi, np.nan), origin="lower", extent=[x0, x1, y0, y1], vmin=0, vmax=1, cmap="magma_r")
            axis.set_title(f"phi at u = {u:.4g} mm", fontsize=9)
            axis.set_xticks([])
            axis.set_yticks([])
        fig.colorbar(image, ax=axis, fraction=0.046)
    save(fig, path)
