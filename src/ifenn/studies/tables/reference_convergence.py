"""Which discretisation is right after the peak: IFENN and its FEM reference against a finer FEM.

Verified IFENN is certified against the pixel equation (phi at the Gauss points, spacing h/2),
while the FEM run it is compared with solves the Q1 phase field on the nodes (spacing h). Where the
two disagree after the peak, the question is which of the two is closer to the answer of a finer
mesh. A case (config ``reference_convergence``) names a FEM run at h, a FEM run of the same specimen
and schedule on a finer mesh, and IFENN runs that continue (or replace) the one at h.

Every curve is compared on one window: the increments with u after the peak of FEM at h, up to the
end of its schedule. Within it each curve's |F| at its own increments is compared with a reference
interpolated at its u; the RMS and the largest difference are divided by the peak of FEM at h (the
same normaliser as the post-switch figures of accuracy.csv). The rows:

- ``fem``: FEM at h against the finer FEM (its own discretisation error after the peak);
- one per IFENN run: against FEM at h (``rms_vs_fem``, what accuracy.csv and whole_path.csv judge)
  and against the finer FEM (``rms_vs_fine``).

``closer_to_fine`` says whether the run is nearer the finer FEM than FEM at h is. Where the load
drops, ``u_half_drop`` is where |F| first falls below half of the peak of FEM at h (NaN if never).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ifenn.run_files import read_history
from ifenn.studies.tables.metrics import fine_label


def _curve(history: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    return history.u.to_numpy(), np.abs(history.reaction_force.to_numpy())


def _half_drop(u: np.ndarray, force: np.ndarray, peak: float) -> float:
    k = int(np.argmax(force))
    below = np.nonzero(force[k:] < 0.5 * peak)[0]
    return float(u[k + below[0]]) if below.size else np.nan


def _difference(u: np.ndarray, force: np.ndarray, reference: tuple[np.ndarray, np.ndarray], window: tuple[float, float],
                peak: float) -> tuple[float, float, int]:
    """RMS and largest |F| - |F_ref| over the curve's increments in the window, / peak."""
    inside = (u > window[0] + 1e-15) & (u <= window[1] + 1e-15)
    if not inside.any():
        return np.nan, np.nan, 0
    error = force[inside] - np.interp(u[inside], *reference)
    return float(np.sqrt(np.mean(error**2)) / peak), float(np.abs(error).max() / peak), int(inside.sum())


def reference_convergence_rows(fem: pd.DataFrame, fine: pd.DataFrame, ifenn: dict[str, pd.DataFrame]) -> list[dict]:
    """Rows of one case (module doc): ``fem`` and ``fine`` the FEM histories at h and on the finer
    mesh, ``ifenn`` run name -> history. Fractions, not percent."""
    coarse, refined = _curve(fem), _curve(fine)
    k_peak = int(np.argmax(coarse[1]))
    peak, window = coarse[1][k_peak], (coarse[0][k_peak], coarse[0][-1])
    u_fine_end = refined[0][-1]
    if u_fine_end + 1e-15 < window[1]:
        raise ValueError(f"the finer FEM run ends at u = {u_fine_end:g}, before the FEM run at h ({window[1]:g}): "
                         "the two must share the schedule")
    base = {"peak_force_fem": peak, "u_peak_fem": window[0], "peak_force_fine": refined[1].max(),
            "u_peak_fine": refined[0][int(np.argmax(refined[1]))], "u_half_drop_fem": _half_drop(*coarse, peak),
            "u_half_drop_fine": _half_drop(*refined, peak)}
    fem_rms, fem_max, fem_n = _difference(*coarse, refined, window, peak)
    rows = [{"method": "fem", "run": "", "window_increments": fem_n, "rms_vs_fem": 0.0, "max_vs_fem": 0.0,
             "rms_vs_fine": fem_rms, "max_vs_fine": fem_max, "peak_force": peak, "u_peak": window[0],
             "u_half_drop": base["u_half_drop_fem"], "closer_to_fine": False, **base}]
    for run, history in ifenn.items():
        u, force = _curve(history)
        rms_fem, max_fem, n = _difference(u, force, coarse, window, peak)
        rms_fine, max_fine, _ = _difference(u, force, refined, window, peak)
        rows.append({"method": "ifenn", "run": run, "window_increments": n, "rms_vs_fem": rms_fem, "max_vs_fem": max_fem,
                     "rms_vs_fine": rms_fine, "max_vs_fine": max_fine, "peak_force": force.max(),
                     "u_peak": float(u[int(np.argmax(force))]), "u_half_drop": _half_drop(u, force, peak),
                     "closer_to_fine": bool(rms_fine < fem_rms), **base})
    return rows


def reference_convergence_table(cases: dict[str, dict]) -> pd.DataFrame:
    """``cases``: case -> {"fem_run", "fine_fem_run", "fem_dir", "fine_dir", "ifenn_dirs": {run: dir}}."""
    rows = []
    for case, where in cases.items():
        ifenn = {run: read_history(path) for run, path in where["ifenn_dirs"].items()}
        for row in reference_convergence_rows(read_history(where["fem_dir"]), read_history(where["fine_dir"]), ifenn):
            rows.append({"case": case, "fem_run": where["fem_run"], "fine_fem_run": where["fine_fem_run"],
                         "fine_reference": f"{Path(where['fine_dir']).parent.name}/{Path(where['fine_dir']).name}", **row})
    return pd.DataFrame(rows)


def reference_convergence_curves(cases: dict[str, dict]) -> dict[str, dict[str, pd.DataFrame]]:
    """case -> {label: history} for the figure: FEM at h, the finer FEM, then the IFENN runs."""
    curves = {}
    for case, where in cases.items():
        curves[case] = {f"FEM {where['fem_run']}": read_history(where["fem_dir"]),
                        fine_label(where): read_history(where["fine_dir"]),
                        **{f"IFENN {run}": read_history(path) for run, path in where["ifenn_dirs"].items()}}
    return curves

