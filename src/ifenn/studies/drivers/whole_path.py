"""IFENN over the whole load path: a run that switches over at the start (config
``switch_over: start``) against the FEM run of the same scene and schedule.

Both runs take the same loads from u = 0; neither copies the other. What is compared:

- the peak force and the u at the peak (relative to FEM's);
- the post-peak force error: over the IFENN increments with u > FEM's u at the peak (and within
  FEM's u range), |F_IFENN| - |F_FEM| with FEM interpolated at IFENN's u; RMS and largest value,
  divided by FEM's peak;
- the final force over FEM's peak, against FEM's own;
- where the load drop passes half of FEM's peak, in u (``u_half_drop_*``; NaN where it does not):
  in a brittle drop a small shift in u is a large force error.

Each is marked as met against ``targets`` (config 'whole_path.targets', fractions). The stages:
"pre-nucleation" = the increments before FEM's phi-threshold increment (max nodal phi >
``switch_phi_max``: the increments the paper's IFENN never computes, where AT2 spreads weak smooth
damage over the whole specimen), "propagation" = from it on. Per stage the verified step's work
is summarised from the run's history (share of the image corrected, whole-image CG iterations,
max |r| of the candidate before and after the correction).

:func:`network_before_nucleation` replays the FEM run's saved states before the switch-over
through the network (full image, no smoothing) and the exact pixel solve of the same H: what the
network makes of the diffuse damage, measured in the max norm and against the check's tolerance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ifenn import run_files
from ifenn.run_files import read_history, read_spec

DEFAULT_TARGETS = {"peak_force": 0.01, "u_peak": 0.02, "post_peak_rms": 0.02, "final_force": 0.02}

#: verified-step columns of history.csv summarised per stage: (column, statistic)
STAGE_COLUMNS = {"verify_corrected_fraction": "mean", "verify_solve_work": "mean", "verify_residual_before": "median",
                 "verify_residual_after": "max", "t_phase_field_s": "mean"}


def _threshold_increment(history: pd.DataFrame, switch_phi_max: float) -> int:
    """First increment whose phi_max exceeds the threshold (one past the last if none)."""
    over = history.increment[history.phi_max > switch_phi_max]
    return int(over.iloc[0]) if len(over) else int(history.increment.iloc[-1]) + 1


def whole_path_comparison(fem: pd.DataFrame, ifenn: pd.DataFrame, switch_phi_max: float, targets: dict | None = None) -> dict:
    """One row: a whole-path IFENN history against the FEM history of the same scene and schedule
    (module doc). Forces are compared as magnitudes; fractions, not percent."""
    targets = {**DEFAULT_TARGETS, **(targets or {})}
    u_fem, f_fem = fem.u.to_numpy(), np.abs(fem.reaction_force.to_numpy())
    u_ifenn, f_ifenn = ifenn.u.to_numpy(), np.abs(ifenn.reaction_force.to_numpy())
    k_fem, k_ifenn = int(np.argmax(f_fem)), int(np.argmax(f_ifenn))
    peak = f_fem[k_fem]
    after = (u_ifenn > u_fem[k_fem] + 1e-15) & (u_ifenn <= u_fem[-1] + 1e-15)
    error = f_ifenn[after] - np.interp(u_ifenn[after], u_fem, f_fem)
    row = {
        "increments_fem": len(fem), "increments_ifenn": len(ifenn),
        "hybrid_increments": int((ifenn.hybrid_active == 1).sum()) if "hybrid_active" in ifenn else len(ifenn),
        "peak_force_fem": peak, "peak_force_ifenn": f_ifenn[k_ifenn], "peak_force_rel_error": f_ifenn[k_ifenn] / peak - 1.0,
        "u_peak_fem": u_fem[k_fem], "u_peak_ifenn": u_ifenn[k_ifenn], "u_peak_rel_error": u_ifenn[k_ifenn] / u_fem[k_fem] - 1.0,
        "post_peak_increments": int(after.sum()),
        "post_peak_rms_error": float(np.sqrt(np.mean(error**2)) / peak) if after.any() else np.nan,
        "post_peak_max_error": float(np.abs(error).max() / peak) if after.any() else np.nan,
        "final_force_fraction_fem": f_fem[-1] / peak, "final_force_fraction_ifenn": f_ifenn[-1] / peak,
    }
    # where the load drop passes half of FEM's peak (a brittle drop: a small shift in u is a large force error)
    for method, u, f, k in (("fem", u_fem, f_fem, k_fem), ("ifenn", u_ifenn, f_ifenn, k_ifenn)):
        below = np.nonzero(f[k:] < 0.5 * peak)[0]
        row[f"u_half_drop_{method}"] = float(u[k + below[0]]) if below.size else np.nan
    row["u_half_drop_rel_error"] = row["u_half_drop_ifenn"] / row["u_half_drop_fem"] - 1.0
    row["meets_peak_force"] = bool(abs(row["peak_force_rel_error"]) <= targets["peak_force"])
    row["meets_u_peak"] = bool(abs(row["u_peak_rel_error"]) <= targets["u_peak"])
    row["meets_post_peak_rms"] = bool(row["post_peak_rms_error"] <= targets["post_peak_rms"])
    row["meets_final_force"] = bool(row["final_force_fraction_ifenn"] <= row["final_force_fraction_fem"] + targets["final_force"])
    row["meets_all"] = all(row[k] for k in ("meets_peak_force", "meets_u_peak", "meets_post_peak_rms", "meets_final_force"))
    # stages, by FEM's phi threshold (where the paper's IFENN would take over)
    nucleation = _threshold_increment(fem, switch_phi_max)
    row["fem_switch_increment"] = nucleation
    row["u_fem_switch"] = float(fem.u[fem.increment == nucleation].iloc[0]) if nucleation <= len(fem) else np.nan
    for stage, rows in (("pre_nucleation", ifenn[ifenn.increment < nucleation]), ("propagation", ifenn[ifenn.increment >= nucleation])):
        row[f"{stage}_increments"] = len(rows)
        for column, statistic in STAGE_COLUMNS.items():
            values = rows[column] if column in rows else pd.Series(dtype=float)
            row[f"{stage}_{column}_{statistic}"] = float(getattr(values, statistic)()) if len(values) else np.nan
    for method, history in (("fem", fem), ("ifenn", ifenn)):
        row[f"t_phase_field_total_s_{method}"] = float(history.t_phase_field_s.sum())
        row[f"t_increment_total_s_{method}"] = float(history.t_increment_s.sum())
    return row


def whole_path_table(runs: dict[str, dict], targets: dict | None = None) -> pd.DataFrame:
    """``runs``: whole-path IFENN run -> {"fem_run": name, "fem_dir": ..., "ifenn_dir": ...};
    the histories and the switch threshold (of the FEM run's spec.json) are read there."""
    rows = []
    for run, where in runs.items():
        fem, ifenn = read_history(where["fem_dir"]), read_history(where["ifenn_dir"])
        switch_phi_max = read_spec(where["fem_dir"])["switch_phi_max"]
        rows.append({"run": run, "fem_run": where["fem_run"], **whole_path_comparison(fem, ifenn, switch_phi_max, targets)})
    return pd.DataFrame(rows)


def network_before_nucleation(spec: dict, fem_fields: str | Path, model_path: str | Path, ifenn_history: pd.DataFrame | None = None,
                              after: int = 2, device="auto") -> pd.DataFrame:
    """The FEM run's saved states before its switch-over increment (and ``after`` saved states
    from it on, for contrast), each H capped and passed through the network (full image, the
    run's evaluation, no smoothing) and the exact pixel solve. Per state: u, FEM's max phi, the
    exact pixel solution's max and its largest difference from FEM's Gauss-point phi, the
    network's largest and mean |phi - exact|, its mean error where exact < 0.1 (the far field),
    its largest normalised residual max |r| (the check's quantity; >= the largest error) and the
    share of pixels with |r| above the verification tolerance. With ``ifenn_history`` (the
    whole-path run's), its verified step's record at that increment is added. ``device``: where the
    network runs (:mod:`ifenn.device`)."""
    from ifenn.hybrid.runs import network_inference, slit_cuts
    from ifenn.pixel_equation.numpy_backend import PixelEquation, solve_pixel_equation

    network_spec = {**spec, "inference": "full", "smoothing_sigma": None}
    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    tolerance = (spec.get("verification") or {}).get("tolerance", 1e-3)
    attrs, saved = run_files.fields_attrs(fem_fields), run_files.saved_increments(fem_fields)
    h_px, switch = float(attrs["h_px"]), int(attrs["switch_increment"])
    before = [k for k in saved if switch <= 0 or k < switch]
    later = [k for k in saved if switch > 0 and k >= switch][:after]
    states = {s["increment"]: (s["u"], s["history"], s["phase_field_gp"])
              for s in run_files.read_states(fem_fields, before + later, keys=run_files.MAP_KEYS)}
    cuts = slit_cuts(spec)
    equation = PixelEquation(Gc, lc, h_px, spec["pixel_padding"], cuts)
    network = network_inference(network_spec, model_path, h_px, next(iter(states.values()))[1].shape, device)
    rows = []
    for k, (u, history, phi_fem) in states.items():
        capped = np.clip(history, 0.0, spec["history_cap"])
        exact = solve_pixel_equation(capped, Gc, lc, h_px, spec["pixel_padding"], rtol=1e-12, cuts=cuts)
        predicted = np.asarray(network(capped), dtype=np.float64)
        error = np.abs(predicted - exact)
        r = np.abs(equation.residual_on(predicted, capped, (slice(0, capped.shape[0]), slice(0, capped.shape[1]))))
        far = exact < 0.1
        row = {"increment": k, "u": u, "stage": "pre_nucleation" if switch <= 0 or k < switch else "propagation",
               "history_max": float(history.max()), "phi_fem_max": float(phi_fem.max()), "phi_fem_mean": float(phi_fem.mean()),
               "phi_exact_max": float(exact.max()), "phi_exact_mean": float(exact.mean()),
               "exact_vs_fem_max_abs": float(np.abs(exact - phi_fem).max()),
               "network_max_abs_error": float(error.max()), "network_mean_abs_error": float(error.mean()),
               "network_far_field_mean_error": float((predicted - exact)[far].mean()) if far.any() else np.nan,
               "network_residual_max": float(r.max()), "network_failing_fraction": float(np.mean(r > tolerance))}
        if ifenn_history is not None and (ifenn_history.increment == k).any():
            record = ifenn_history[ifenn_history.increment == k].iloc[0]
            for column in ("verify_corrected_fraction", "verify_solve_work", "verify_residual_before", "verify_residual_after"):
                row[f"run_{column}"] = float(record[column]) if column in record else np.nan
        rows.append(row)
    return pd.DataFrame(rows)
