"""Speed against accuracy (issue 5): every method variant of a scene as a point, wall time
(whole run and propagation stage) against the force-curve error versus a reference run.

Reference: a FEM run named in the config (the finest schedule with converged staggering,
'snt1-III-conv' for snt1). Error: relative L2(u) error of the force curve over the common u
range (metrics.force_curve_error). Wall time: the sum of the per-increment times recorded in
history.csv (an IFENN run's history holds the FEM increments it continued, so its whole-run
time includes the FEM stage before the switch-over); propagation stage = the increments after
the switch-over (the first increment with phi_max > switch_phi_max; for a whole-path IFENN run,
which computes every increment (its variant ends in 'whole path'), the first of its own increments with
phi_max > switch_phi_max, as for a FEM run). Wall times depend on the
load of the machine while each run was made; 'displacement_solves' is the load-independent
cost (each staggered iteration is one displacement solve and one phase-field step).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .config import switch_over
from .metrics import force_curve_error


def _label(config: dict, method: str, run: str) -> str:
    if method == "fem":
        entry = config["fem_runs"][run]
        stagger = "converged" if entry.get("stagger_max_iterations", config["solver"]["stagger_max_iterations"]) > 1 else "single pass"
        solver = entry.get("linear_solvers", config["solver"]["linear_solvers"])
        return f"FEM {entry['schedule']}, {stagger}, {solver}"
    entry = config["ifenn_runs"][run]
    fem = config["fem_runs"][entry["fem_run"]]
    stagger = "converged" if fem.get("stagger_max_iterations", config["solver"]["stagger_max_iterations"]) > 1 else "single pass"
    predictor = entry.get("predictor", config["ifenn"]["predictor"])
    inference = entry.get("inference", config["ifenn"]["inference"])
    what = "exact pixel solve" if predictor == "exact_pixel" else ("PICNN process zone" if inference == "process_zone" else "PICNN full image")
    verification = {**config["ifenn"].get("verification", {}), **entry.get("verification", {})}
    if verification.get("enabled"):
        what = "verified, no network" if verification.get("warm_start") == "previous" else f"verified {what}"
    if switch_over(config, run)[0] == "start":
        what += ", whole path"
    return f"IFENN {fem['schedule']}, {stagger}, {what}"


def pareto_front(time: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Mask of the points no other point beats in both time and error (ties count as not beaten)."""
    time, error = np.asarray(time, float), np.asarray(error, float)
    front = np.ones(len(time), bool)
    for i in range(len(time)):
        better = (time <= time[i]) & (error <= error[i]) & ((time < time[i]) | (error < error[i]))
        front[i] = not better.any()
    return front


def speed_accuracy_table(config: dict, results: str | Path = "results") -> pd.DataFrame:
    results = Path(results)
    rows = []
    for scene, setup in config["speed_accuracy"].items():
        ref = pd.read_csv(results / "fem" / setup["reference"] / "history.csv")
        for method in ("fem", "ifenn"):
            for run in setup.get(method, []):
                history = pd.read_csv(results / method / run / "history.csv")
                switch = history.increment[history.phi_max > config["ifenn"]["switch_phi_max"]]
                switch = int(switch.iloc[0]) if len(switch) else int(history.increment.iloc[-1])
                whole = method == "ifenn" and switch_over(config, run)[0] == "start"
                if method == "ifenn" and not whole and (history.hybrid_active == 1).any():
                    switch = int(history.increment[history.hybrid_active == 1].min()) - 1
                fem_run = run if method == "fem" else config["ifenn_runs"][run]["fem_run"]
                fem_entry = config["fem_runs"][fem_run]
                rows.append({
                    "scene": scene, "method": method, "run": run, "variant": _label(config, method, run),
                    "schedule": fem_entry["schedule"],
                    "converged": fem_entry.get("stagger_max_iterations", config["solver"]["stagger_max_iterations"]) > 1,
                    "increments": len(history), "stagger_iterations": int(history.stagger_iterations.sum()),
                    # load-independent cost: every displacement solve, rejected adaptive attempts included
                    "displacement_solves": int(history.stagger_iterations.sum()
                                               + (history.rejected_iterations.sum() if "rejected_iterations" in history else 0)),
                    "wall_s": float(history.t_increment_s.sum()),
                    "propagation_wall_s": float(history.t_increment_s[history.increment > switch].sum()),
                    "force_l2_rel_error": force_curve_error(history.u.to_numpy(), history.reaction_force.to_numpy(),
                                                            ref.u.to_numpy(), ref.reaction_force.to_numpy()),
                    "peak_force": float(history.reaction_force.max()),
                    "peak_force_rel_error": float(history.reaction_force.max() / ref.reaction_force.max() - 1.0),
                    "reference": setup["reference"], "is_reference": method == "fem" and run == setup["reference"],
                })
    table = pd.DataFrame(rows)
    for column in ("wall_s", "propagation_wall_s"):
        table[f"pareto_{column}"] = False
        for scene in table.scene.unique():
            mask = (table.scene == scene) & ~table.is_reference
            table.loc[mask, f"pareto_{column}"] = pareto_front(table.loc[mask, column], table.loc[mask, "force_l2_rel_error"])
    return table
