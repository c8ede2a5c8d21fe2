"""Accuracy of an IFENN run against the FEM run it continues, and per-step timings.

All field metrics use the Gauss-point phase field as pixel maps (both methods have it), so
FEM and IFENN are measured with the same discrete operators.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import scipy.ndimage

from ifenn.run_files import FIELDS, SPEC, read_history, read_phase_field_maps, read_spec

CRACK_PHI = 0.5


def dissipated_energy(phase_field: np.ndarray, h_px: float, Gc: float, lc: float) -> float:
    """Crack surface energy int Gc/(2 lc) (phi^2 + lc^2 |grad phi|^2) dA on a pixel map,
    N mm per mm of thickness. The gradient term is summed over pixel faces ((delta phi / h)^2
    h^2 per face): unlike centred differences it keeps the kink of phi on the crack line."""
    bulk = (phase_field**2).sum() * h_px**2
    faces = (np.diff(phase_field, axis=0) ** 2).sum() + (np.diff(phase_field, axis=1) ** 2).sum()
    return float(Gc / (2.0 * lc) * bulk + 0.5 * Gc * lc * faces)


def crack_iou(phi_a: np.ndarray, phi_b: np.ndarray, threshold: float = CRACK_PHI) -> float:
    """Intersection over union of the crack sets {phi >= threshold}; 1.0 when both are empty."""
    a, b = phi_a >= threshold, phi_b >= threshold
    union = np.logical_or(a, b).sum()
    return 1.0 if union == 0 else float(np.logical_and(a, b).sum() / union)


def force_curve_error(u: np.ndarray, force: np.ndarray, u_ref: np.ndarray, force_ref: np.ndarray, points: int = 4000) -> float:
    """Relative L2 error of a force-displacement curve against a reference, in the norm of
    L2(u) over the common u range: both curves interpolated linearly onto ``points``
    uniform u values, so runs with different load steps compare fairly."""
    lo, hi = max(u[0], u_ref[0]), min(u[-1], u_ref[-1])
    grid = np.linspace(lo, hi, points)
    a, b = np.interp(grid, u, force), np.interp(grid, u_ref, force_ref)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def peak(u: np.ndarray, force: np.ndarray) -> tuple[float, float]:
    """(largest force, the displacement where it is first reached)."""
    k = int(np.argmax(force))
    return float(force[k]), float(u[k])


def work_of_load(u: np.ndarray, force: np.ndarray, u_end: float) -> float:
    """Area under the force over the displacement from the first point to ``u_end`` (trapezoids,
    the curve interpolated linearly at ``u_end``): once the specimen is cut, the energy its
    fracture dissipated. It compares two answers without depending on where the drop falls."""
    u, force = np.asarray(u, dtype=float), np.asarray(force, dtype=float)
    inside = u < u_end
    uu = np.append(u[inside], u_end)
    ff = np.append(force[inside], np.interp(u_end, u, force))
    return float(np.sum(0.5 * (ff[1:] + ff[:-1]) * np.diff(uu)))


def work_rel_error(u: np.ndarray, force: np.ndarray, u_ref: np.ndarray, force_ref: np.ndarray) -> float:
    """The work of the load against a reference's, both up to the end of the shorter curve, - 1."""
    u_end = min(u[-1], u_ref[-1])
    return work_of_load(u, force, u_end) / work_of_load(u_ref, force_ref, u_end) - 1.0


def u_at_half_drop(u: np.ndarray, force: np.ndarray) -> float:
    """The displacement where the force, after its peak, first falls to half the peak
    (interpolated linearly between increments); NaN if it never does."""
    u, force = np.asarray(u, dtype=float), np.asarray(force, dtype=float)
    k = int(np.argmax(force))
    half = 0.5 * force[k]
    below = np.nonzero(force[k:] <= half)[0]
    if len(below) == 0:
        return float("nan")
    j = k + int(below[0])
    return float(np.interp(half, [force[j], force[j - 1]], [u[j], u[j - 1]]))


def fine_label(where: dict) -> str:
    """A case's finer reference in a legend: the uniform FEM run, or its adaptive-mesh run
    (config ``finer_references``), from the reference's directory."""
    name = str(where["fine_dir"]).rstrip("/").split("/")[-1]
    kind = "adaptive mesh" if "/adaptive/" in f"/{where['fine_dir']}" else "FEM"
    return f"{kind} {name} (finer)"


def post_peak_rms(u: np.ndarray, force: np.ndarray, u_ref: np.ndarray, force_ref: np.ndarray) -> float:
    """RMS of |F| - |F_ref| (the reference curve interpolated at the run's u) over the run's
    increments after the reference's peak and within its u range, over the reference's peak
    (a fraction); NaN when the run has no such increment."""
    force, force_ref = np.abs(force), np.abs(force_ref)
    k = int(np.argmax(force_ref))
    after = (u > u_ref[k] + 1e-15) & (u <= u_ref[-1] + 1e-15)
    if not after.any():
        return np.nan
    error = force[after] - np.interp(u[after], u_ref, force_ref)
    return float(np.sqrt(np.mean(error**2)) / force_ref[k])


def post_switch_force_error(fem: pd.DataFrame, ifenn: pd.DataFrame) -> dict:
    """IFENN against FEM where the two can differ, after the switch-over: over the hybrid
    increments (within FEM's u range), the RMS and the largest |F_IFENN| - |F_FEM| (FEM
    interpolated at IFENN's u), divided by FEM's peak force. NaN without hybrid increments."""
    u_fem, f_fem = fem.u.to_numpy(), np.abs(fem.reaction_force.to_numpy())
    hybrid = ifenn[(ifenn.hybrid_active == 1) & (ifenn.u <= u_fem[-1] + 1e-15)]
    if hybrid.empty:
        return {"post_switch_increments": 0, "post_switch_rms_error": np.nan, "post_switch_max_error": np.nan}
    error = np.abs(hybrid.reaction_force.to_numpy()) - np.interp(hybrid.u.to_numpy(), u_fem, f_fem)
    peak = f_fem.max()
    return {"post_switch_increments": len(hybrid), "post_switch_rms_error": float(np.sqrt(np.mean(error**2)) / peak),
            "post_switch_max_error": float(np.abs(error).max() / peak)}


def _notch_tips(scene: dict, pixels) -> list[tuple[tuple[int, int], tuple[int, int] | None]]:
    """(tip pixel, pixel where the notch meets the boundary or None) of every notch end inside
    the domain (the ends a crack starts from); pixels as (row, column)."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    tol = 1e-9 * max(x1 - x0, y1 - y0)

    def pixel(point):
        col = min(max(int((point[0] - pixels["x0"]) / pixels["h_px"]), 0), int(pixels["nx_px"]) - 1)
        row = min(max(int((point[1] - pixels["y0"]) / pixels["h_px"]), 0), int(pixels["ny_px"]) - 1)
        return row, col

    def inside(point):
        return x0 + tol < point[0] < x1 - tol and y0 + tol < point[1] < y1 - tol

    tips = []
    for notch in scene.get("notches", []):
        for end, other in ((notch["start"], notch["end"]), (notch["end"], notch["start"])):
            if inside(end):
                tips.append((pixel(end), None if inside(other) else pixel(other)))
    return tips


def crack_ridge_phi(phase_field: np.ndarray, tips: list, tip_radius: int = 3, edge_clearance: int = 8) -> float:
    """The phase field at the weakest point of the crack: the largest t for which the set
    {phi >= t} connects what the crack must connect, i.e. every notch tip with the others (two
    or more tips: the cracks meet), or the one tip with the image boundary away from its notch
    (one tip: the crack cuts through). Every path between them drops to t somewhere, so t is
    the largest phi across the band at the crack's weakest section (the stiffness left there
    is (1 - t)^2). ``tips``: (tip pixel, the notch's boundary pixel or None), as of
    ``_notch_tips``; tips count as discs of ``tip_radius`` pixels; boundary pixels within
    ``edge_clearance`` of the notch's own boundary pixel do not count. NaN without a tip."""
    if not tips:
        return float("nan")
    ny, nx = phase_field.shape
    rows, cols = np.mgrid[0:ny, 0:nx]
    discs = [(rows - r) ** 2 + (cols - c) ** 2 <= tip_radius**2 for (r, c), _ in tips]
    if len(tips) == 1:
        boundary = np.zeros_like(phase_field, dtype=bool)
        boundary[[0, -1], :] = boundary[:, [0, -1]] = True
        mouth = tips[0][1]
        if mouth is not None:
            boundary &= np.maximum(np.abs(rows - mouth[0]), np.abs(cols - mouth[1])) > edge_clearance
        targets = [discs[0], boundary]
    else:
        targets = discs
    structure = np.ones((3, 3), int)

    def connected(t: float) -> bool:
        labels, _ = scipy.ndimage.label(phase_field >= t, structure=structure)
        common = None
        for target in targets:
            found = set(np.unique(labels[target]).tolist()) - {0}
            common = found if common is None else common & found
            if not common:
                return False
        return True

    lo, hi = 0.0, float(phase_field.max())
    if not connected(1e-12):
        return 0.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if connected(mid) else (lo, mid)
    return lo


def _nearest(maps: dict, u: float) -> int:
    return min(maps, key=lambda k: abs(maps[k][0] - u))


def accuracy(fem_dir: str | Path, ifenn_dir: str | Path, levels: int = 3) -> dict:
    """Force-curve and crack metrics of an IFENN run against its FEM run (same scene and
    schedule; adaptive schedules are compared at equal u). The material (Gc, lc of the
    dissipated energy) is the one the IFENN run used (its spec.json)."""
    material = read_spec(ifenn_dir)["material"]
    fem = read_history(fem_dir)
    ifenn = read_history(ifenn_dir)
    f_fem, f_ifenn = fem.reaction_force.to_numpy(), ifenn.reaction_force.to_numpy()
    peak_fem, peak_ifenn = int(np.argmax(f_fem)), int(np.argmax(f_ifenn))
    switch = int(ifenn.increment[ifenn.hybrid_active == 1].min()) if (ifenn.hybrid_active == 1).any() else len(ifenn) + 1
    row = {
        "switch_increment": switch, "u_switch": float(ifenn.u[ifenn.increment == switch].iloc[0]) if switch <= len(ifenn) else np.nan,
        "peak_force_fem": f_fem[peak_fem], "peak_force_ifenn": f_ifenn[peak_ifenn],
        "peak_force_rel_error": (f_ifenn[peak_ifenn] - f_fem[peak_fem]) / f_fem[peak_fem],
        "u_peak_fem": float(fem.u.iloc[peak_fem]), "u_peak_ifenn": float(ifenn.u.iloc[peak_ifenn]),
        "force_l2_rel_error": force_curve_error(ifenn.u.to_numpy(), f_ifenn, fem.u.to_numpy(), f_fem),
        "final_force_fraction_fem": f_fem[-1] / f_fem[peak_fem], "final_force_fraction_ifenn": f_ifenn[-1] / f_fem[peak_fem],
        **post_switch_force_error(fem, ifenn),
    }
    fem_maps, attrs = read_phase_field_maps(Path(fem_dir) / FIELDS)
    ifenn_maps, _ = read_phase_field_maps(Path(ifenn_dir) / FIELDS)
    h_px = float(attrs["h_px"])
    last_fem = max(fem_maps)
    last_ifenn = _nearest(ifenn_maps, fem_maps[last_fem][0])
    row["dissipated_energy_fem"] = dissipated_energy(fem_maps[last_fem][1], h_px, material["Gc"], material["lc"])
    row["dissipated_energy_ifenn"] = dissipated_energy(ifenn_maps[last_ifenn][1], h_px, material["Gc"], material["lc"])
    row["dissipated_energy_rel_error"] = row["dissipated_energy_ifenn"] / row["dissipated_energy_fem"] - 1.0
    if (Path(fem_dir) / SPEC).exists():
        tips = _notch_tips(read_spec(fem_dir)["scene"], attrs)
        row["crack_ridge_phi_fem"] = crack_ridge_phi(fem_maps[last_fem][1], tips)
        row["crack_ridge_phi_ifenn"] = crack_ridge_phi(ifenn_maps[last_ifenn][1], tips)
    u_switch = row["u_switch"] if np.isfinite(row["u_switch"]) else np.inf
    after = sorted(i for i in fem_maps if fem_maps[i][0] > u_switch)
    picks = [after[int(round(k))] for k in np.linspace(0, len(after) - 1, levels)] if after else []
    for k in range(levels):
        if k < len(picks):
            row[f"u_iou_{k + 1}"] = fem_maps[picks[k]][0]
            row[f"crack_iou_{k + 1}"] = crack_iou(fem_maps[picks[k]][1], ifenn_maps[_nearest(ifenn_maps, fem_maps[picks[k]][0])][1])
        else:
            row[f"u_iou_{k + 1}"] = row[f"crack_iou_{k + 1}"] = np.nan
    return row


def timing(fem_history: pd.DataFrame, ifenn_history: pd.DataFrame) -> list[dict]:
    """Mean seconds per increment of each step, FEM and IFENN, over the propagation stage
    (the increments IFENN computed); cumulative phase-field time over that stage."""
    hybrid = ifenn_history[ifenn_history.hybrid_active == 1]
    # after the switch-over; with adaptive steps the two runs may take different increments
    stage = fem_history[fem_history.increment >= hybrid.increment.min()]
    rows = []
    for method, frame in (("fem", stage), ("ifenn", hybrid)):
        rows.append({
            "method": method, "increments": len(frame),
            "t_displacement_s": frame.t_displacement_s.mean(), "t_phase_field_s": frame.t_phase_field_s.mean(),
            "t_inference_s": frame.t_inference_s.mean() if "t_inference_s" in frame else 0.0,
            "t_verify_s": frame.t_verify_s.mean() if "t_verify_s" in frame else 0.0,
            "t_history_s": frame.t_history_s.mean(), "t_increment_s": frame.t_increment_s.mean(),
            "phase_field_cumulative_s": frame.t_phase_field_s.sum(), "run_cumulative_s": frame.t_increment_s.sum(),
        })
    fem_row, ifenn_row = rows
    for row in rows:
        row["phase_field_time_vs_fem"] = row["t_phase_field_s"] / fem_row["t_phase_field_s"]
        row["increment_time_vs_fem"] = row["t_increment_s"] / fem_row["t_increment_s"]
    return rows


def process_zone_pairs(config: dict) -> dict[str, str]:
    """Process-zone IFENN run -> its full-image twin: the run of 'ifenn_runs' whose entry is the
    same but for ``inference`` (resolving to 'full'). Runs without a twin are left out."""
    def resolved(entry):
        return entry.get("inference", config["ifenn"]["inference"])

    def rest(entry):
        return {k: v for k, v in entry.items() if k not in ("inference", "process_zone")}

    runs = config["ifenn_runs"]
    pairs = {}
    for zone, entry in runs.items():
        if resolved(entry) != "process_zone":
            continue
        twins = [name for name, other in runs.items() if resolved(other) == "full" and rest(other) == rest(entry)]
        if twins:
            pairs[zone] = twins[0]
    return pairs


def process_zone_agreement(zone_dir: str | Path, full_dir: str | Path) -> dict:
    """How far process-zone IFENN is from full-image IFENN on the same run: force-curve error,
    peak and final force difference, largest |phi| difference and crack IoU at the last saved
    increment; the share of the image whose network output was computed anew and the phase-field step's time of
    each (two runs, so machine load may differ: see the phase-field benchmark for one run)."""
    zone, full = (read_history(d) for d in (zone_dir, full_dir))
    zone_maps, _ = read_phase_field_maps(Path(zone_dir) / FIELDS)
    full_maps, _ = read_phase_field_maps(Path(full_dir) / FIELDS)
    last = max(set(zone_maps) & set(full_maps))
    a, b = zone_maps[last][1], full_maps[last][1]
    hz, hf = zone[zone.hybrid_active == 1], full[full.hybrid_active == 1]
    return {
        "force_l2_rel_error": force_curve_error(zone.u.to_numpy(), zone.reaction_force.to_numpy(),
                                                full.u.to_numpy(), full.reaction_force.to_numpy()),
        "peak_force_rel_diff": zone.reaction_force.max() / full.reaction_force.max() - 1.0,
        "final_force_zone": float(zone.reaction_force.iloc[-1]), "final_force_full": float(full.reaction_force.iloc[-1]),
        "u_compared": zone_maps[last][0], "phi_max_abs_diff": float(np.abs(a - b).max()), "crack_iou": crack_iou(a, b),
        "hybrid_increments": len(hz), "evaluated_fraction_mean": float(hz.evaluated_fraction.mean()),
        "t_phase_field_zone_s": float(hz.t_phase_field_s.mean()), "t_phase_field_full_s": float(hf.t_phase_field_s.mean()),
    }
