"""Speed against accuracy: every method variant of a scene as a point, wall time
(whole run and propagation stage) against the force-curve error versus a reference run; FEM,
IFENN and runs on a displacement mesh that follows the crack (``adaptive``).

Reference: a run named in the config (``reference``, of ``reference_method`` fem or adaptive),
converged in the mesh and in the load path: the finest schedule with converged staggering on the
adaptive mesh whose finest cells have the finer uniform FEM's spacing ('snt1-III-conv-adaptive' for
snt1: h/2, the 400 x 400 mesh's), so FEM at h is a point with its own discretisation error like every
other. The finer uniform FEM is a point too: single-pass staggering lags the converged load path
after the peak, by more than the mesh at h errs (measured: docs/decisions.md). Errors: the
relative L2(u) error of the force curve over the common u range (metrics.force_curve_error), the
post-peak force RMS over the reference's peak (metrics.post_peak_rms) and the peak force's; and two
that measure the answer without being dominated by where the drop falls: the work of the load up to
the end of the shorter curve (``work_rel_error``; once the specimen is cut, the dissipated energy)
and the displacement at which the force has fallen to half its peak (``u_half_drop`` and its
``u_half_drop_rel_error``). Wall time: the sum of the per-increment times recorded in
history.csv (an IFENN run's history holds the FEM increments it continued, so its whole-run
time includes the FEM stage before the switch-over); propagation stage = the increments after
the switch-over (the first increment with phi_max > switch_phi_max; for a whole-path IFENN run,
which computes every increment (its variant ends in 'whole path'), the first of its own increments with
phi_max > switch_phi_max, as for a FEM run). Wall times depend on the
load of the machine while each run was made; 'displacement_solves' is the load-independent
cost (each staggered iteration is one displacement solve and one phase-field step). ``role``: what
the chart marks a run as (the config's ``reference``, ``baseline`` and ``combined``), and
``wall_vs_baseline`` its wall over the baseline's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ifenn.run_files import read_history, read_spec
from ifenn.studies.tables.metrics import force_curve_error, post_peak_rms, u_at_half_drop, work_rel_error


def _label(method: str, spec: dict) -> str:
    """A run's variant, from its resolved spec (spec.json)."""
    stagger = "converged" if spec["stagger_max_iterations"] > 1 else "single pass"
    if method == "fem":
        return f"FEM {spec['schedule_name']}, {stagger}, {spec['linear_solvers']}"
    if method == "adaptive":
        step = "verified IFENN" if spec.get("ifenn_run") else "certified pixel solve"
        return f"adaptive mesh {spec['schedule_name']}, {stagger}, {step}"
    what = ("exact pixel solve" if spec["predictor"] == "exact_pixel"
            else ("PICNN process zone" if spec["inference"] == "process_zone" else "PICNN full image"))
    verification = spec.get("verification") or {}
    if verification.get("enabled"):
        what = "verified, no network" if verification.get("warm_start") == "previous" else f"verified {what}"
    if spec.get("switch_over") == "start":
        what += ", whole path"
    return f"IFENN {spec['schedule_name']}, {stagger}, {what}"


def _role(setup: dict, method: str, run: str) -> str:
    """What the chart marks a run as: 'reference', 'baseline' (a FEM run: the one to beat), 'combined', or ''."""
    if method == setup.get("reference_method", "fem") and run == setup["reference"]:
        return "reference"
    if method == "fem" and run == setup.get("baseline"):
        return "baseline"
    return "combined" if run in setup.get("combined", []) else ""


def _drop_and_work(u, force, ref_u, ref_force, ref_half: float) -> dict:
    half = u_at_half_drop(u, force)
    return {"work_rel_error": work_rel_error(u, force, ref_u, ref_force), "u_half_drop": half, "u_half_drop_rel_error": half / ref_half - 1.0}


def pareto_front(time: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Mask of the points no other point beats in both time and error (ties count as not beaten)."""
    time, error = np.asarray(time, float), np.asarray(error, float)
    front = np.ones(len(time), bool)
    for i in range(len(time)):
        better = (time <= time[i]) & (error <= error[i]) & ((time < time[i]) | (error < error[i]))
        front[i] = not better.any()
    return front


def speed_accuracy_table(setups: dict, run_dirs: dict[str, dict[str, str | Path]]) -> pd.DataFrame:
    """``setups``: config 'speed_accuracy' (per scene: reference, fem and ifenn runs);
    ``run_dirs``: {"fem": {run: directory}, "ifenn": {run: directory}, "adaptive": {run: directory}},
    each holding the run's history.csv and spec.json (every option is read from the spec the run
    used). Adaptive-mesh runs (:mod:`ifenn.adaptive`) compute every increment, as FEM does."""
    rows = []
    for scene, setup in setups.items():
        reference_method = setup.get("reference_method", "fem")
        ref = read_history(run_dirs[reference_method][setup["reference"]])
        ref_u, ref_force = ref.u.to_numpy(), ref.reaction_force.to_numpy()
        ref_half = u_at_half_drop(ref_u, ref_force)
        for method in ("fem", "ifenn", "adaptive"):
            for run in setup.get(method, []):
                history, spec = read_history(run_dirs[method][run]), read_spec(run_dirs[method][run])
                switch = history.increment[history.phi_max > spec["switch_phi_max"]]
                switch = int(switch.iloc[0]) if len(switch) else int(history.increment.iloc[-1])
                whole = method == "ifenn" and spec.get("switch_over") == "start"
                if method == "ifenn" and not whole and (history.hybrid_active == 1).any():
                    switch = int(history.increment[history.hybrid_active == 1].min()) - 1
                rows.append({
                    "scene": scene, "method": method, "run": run, "variant": _label(method, spec),
                    "schedule": spec["schedule_name"],
                    "converged": spec["stagger_max_iterations"] > 1,
                    "increments": len(history), "stagger_iterations": int(history.stagger_iterations.sum()),
                    # load-independent cost: every displacement solve, rejected adaptive attempts and
                    # passes redone on a rebuilt mesh included (counted by the adaptive runs themselves)
                    "displacement_solves": int(history.displacement_solves.sum() if "displacement_solves" in history else
                                               history.stagger_iterations.sum()
                                               + (history.rejected_iterations.sum() if "rejected_iterations" in history else 0)),
                    "wall_s": float(history.t_increment_s.sum()),
                    "propagation_wall_s": float(history.t_increment_s[history.increment > switch].sum()),
                    "force_l2_rel_error": force_curve_error(history.u.to_numpy(), history.reaction_force.to_numpy(),
                                                            ref.u.to_numpy(), ref.reaction_force.to_numpy()),
                    "post_peak_rms": post_peak_rms(history.u.to_numpy(), history.reaction_force.to_numpy(),
                                                   ref.u.to_numpy(), ref.reaction_force.to_numpy()),
                    "peak_force": float(history.reaction_force.max()),
                    "peak_force_rel_error": float(history.reaction_force.max() / ref.reaction_force.max() - 1.0),
                    **_drop_and_work(history.u.to_numpy(), history.reaction_force.to_numpy(), ref_u, ref_force, ref_half),
                    "reference": setup["reference"], "role": _role(setup, method, run),
                })
    table = pd.DataFrame(rows)
    table.insert(table.columns.get_loc("reference") + 1, "is_reference", table.role == "reference")
    table["work_abs_error"] = table.work_rel_error.abs()
    # the wall against the scene's baseline (FEM as published), where the config names one
    table["wall_vs_baseline"] = np.nan
    for scene in table.scene.unique():
        base = table[(table.scene == scene) & (table.role == "baseline")]
        if len(base):
            table.loc[table.scene == scene, "wall_vs_baseline"] = table.wall_s[table.scene == scene] / float(base.wall_s.iloc[0])
    # per scene, the runs no other beats in both cost and error: force curve against the whole run's
    # and the propagation stage's wall, work of the load against the whole run's
    for name, column, error in PARETO:
        table[name] = False
        for scene in table.scene.unique():
            mask = (table.scene == scene) & ~table.is_reference
            table.loc[mask, name] = pareto_front(table.loc[mask, column], table.loc[mask, error])
    return table


#: Pareto columns of the speed-accuracy table: (column, wall-time column, error column)
PARETO = (("pareto_wall_s", "wall_s", "force_l2_rel_error"),
          ("pareto_propagation_wall_s", "propagation_wall_s", "force_l2_rel_error"),
          ("pareto_work_wall_s", "wall_s", "work_abs_error"))
