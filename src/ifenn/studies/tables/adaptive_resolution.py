"""Displacement meshes that follow the crack against the converged reference.

A case (config ``adaptive_resolution``) names a FEM run at h, the finer uniform FEM of the same
specimen and schedule (the converged reference) and adaptive runs of the FEM run
(:mod:`ifenn.adaptive`). One row per run, FEM at h included (``method`` "fem-uniform"; the adaptive
runs "fem-adaptive", the certified pixel solve, or "verified-adaptive", the verified IFENN step):

- ``peak_error_vs_fine_pct``: (peak |F| / the finer FEM's peak - 1), percent; ``u_peak_error_vs_fine_pct``
  the same for the displacement at the peak;
- ``work_error_vs_fine_pct``: the work of the load (the area under the force, up to the end of the
  shorter curve: once the specimen is cut, the dissipated energy) against the finer run's, percent;
- ``post_peak_rms_vs_fine_pct``: RMS of |F| - |F_fine| (the finer curve interpolated at the run's
  u) over the run's increments after the finer FEM's peak, over the finer peak, percent;
- ``wall_s`` (provenance.json's wall_time_s, plus ``start_wall_s``, the increments a run took over
  from the run it starts from: :func:`ifenn.config.shared_prefix`) and ``wall_fem_h_s``, the FEM run
  at h's, from the same DAG, and their ratio ``wall_fraction_of_fem_h``;
- ``dofs_fraction_of_fine``: the run's mean displacement dofs over the increments, over those of
  the finer uniform mesh (``fine_uniform_dofs``: 2 per node, the slits' twins included; also where
  the finer reference itself is an adaptive run), and the largest fraction;
- per adaptive run, the rebuilds and the increments whose crack core still left the fine region
  (``outside_fine``: reported, never hidden).

``meets_*`` mark the targets: RMS <= 2 %, |peak error| <= 1 %, |u at the peak| and |work| <= 2 %,
wall <= FEM at h's, mean dofs <= 30 % of the fine mesh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ifenn.run_files import read_history, read_run_wall, read_spec
from ifenn.studies.tables.metrics import fine_label, peak, post_peak_rms, work_rel_error

TARGETS = {"post_peak_rms_pct": 2.0, "peak_error_pct": 1.0, "u_peak_error_pct": 2.0, "work_error_pct": 2.0, "dofs_fraction": 0.30}


def uniform_dofs(scene: dict) -> int:
    """Displacement dofs of a scene's uniform Q1 mesh: 2 per node, the slits' twins included."""
    from ifenn.fem.mesh import build_mesh

    return 2 * len(build_mesh(scene).points)


def resolution_rows(fem: pd.DataFrame, fine: pd.DataFrame, adaptive: dict[str, pd.DataFrame], fine_dofs: int, fem_dofs: int,
                    wall: dict[str, float], methods: dict[str, str] | None = None) -> list[dict]:
    """Rows of one case (module doc); ``wall``: run -> seconds, with "fem" for FEM at h;
    ``methods``: adaptive run -> its method (default "fem-adaptive")."""
    methods = methods or {}
    reference = (fine.u.to_numpy(), np.abs(fine.reaction_force.to_numpy()))
    peak_fine, u_peak_fine = peak(*reference)
    rows = []
    runs = {"": (fem, "fem-uniform"), **{name: (history, methods.get(name, "fem-adaptive")) for name, history in adaptive.items()}}
    for name, (history, method) in runs.items():
        u, force = history.u.to_numpy(), np.abs(history.reaction_force.to_numpy())
        dofs = history.dofs.to_numpy() if "dofs" in history else np.full(len(history), fem_dofs)
        row = {"run": name, "method": method,
               "post_peak_rms_vs_fine_pct": 100 * post_peak_rms(u, force, *reference),
               "peak_error_vs_fine_pct": float(100 * (force.max() / peak_fine - 1)),
               "u_peak_error_vs_fine_pct": float(100 * (peak(u, force)[1] / u_peak_fine - 1)),
               "work_error_vs_fine_pct": 100 * work_rel_error(u, force, *reference),
               "wall_s": wall[name or "fem"], "wall_fem_h_s": wall["fem"], "wall_fraction_of_fem_h": wall[name or "fem"] / wall["fem"],
               "dofs_fraction_of_fine": float(dofs.mean() / fine_dofs), "dofs_fraction_of_fine_max": float(dofs.max() / fine_dofs),
               "fine_uniform_dofs": int(fine_dofs),
               "peak_force": float(force.max()), "peak_force_fine": float(peak_fine),
               "remeshes": int(history.remeshes.sum()) if "remeshes" in history else 0,
               "increments_outside_fine": int(history.outside_fine.sum()) if "outside_fine" in history else 0}
        row["meets_post_peak_rms"] = bool(row["post_peak_rms_vs_fine_pct"] <= TARGETS["post_peak_rms_pct"])
        row["meets_peak"] = bool(abs(row["peak_error_vs_fine_pct"]) <= TARGETS["peak_error_pct"])
        row["meets_u_peak"] = bool(abs(row["u_peak_error_vs_fine_pct"]) <= TARGETS["u_peak_error_pct"])
        row["meets_work"] = bool(abs(row["work_error_vs_fine_pct"]) <= TARGETS["work_error_pct"])
        row["meets_wall"] = bool(row["wall_s"] <= row["wall_fem_h_s"])
        row["meets_dofs"] = bool(row["dofs_fraction_of_fine"] <= TARGETS["dofs_fraction"])
        rows.append(row)
    return rows


def adaptive_resolution_table(cases: dict[str, dict]) -> pd.DataFrame:
    """``cases``: case -> {"fem_run", "fine_fem_run", "fem_dir", "fine_dir", "adaptive_dirs": {run: dir}}."""
    rows = []
    for case, where in cases.items():
        fine_scene, fem_scene = read_spec(where["fine_dir"])["scene"], read_spec(where["fem_dir"])["scene"]
        adaptive = {run: read_history(path) for run, path in where["adaptive_dirs"].items()}
        methods = {run: "verified-adaptive" if read_spec(path).get("ifenn_run") else "fem-adaptive"
                   for run, path in where["adaptive_dirs"].items()}
        wall = {"fem": read_run_wall(where["fem_dir"]), **{run: read_run_wall(path) for run, path in where["adaptive_dirs"].items()}}
        for row in resolution_rows(read_history(where["fem_dir"]), read_history(where["fine_dir"]), adaptive,
                                   uniform_dofs(fine_scene), uniform_dofs(fem_scene), wall, methods):
            rows.append({"case": case, "fem_run": where["fem_run"], "fine_fem_run": where["fine_fem_run"],
                         "fine_reference": f"{Path(where['fine_dir']).parent.name}/{Path(where['fine_dir']).name}",
                         **{**row, "run": row["run"] or where["fem_run"]}})
    return pd.DataFrame(rows)


def adaptive_resolution_curves(cases: dict[str, dict]) -> dict[str, dict[str, pd.DataFrame]]:
    """case -> {label: history} for the figure: FEM at h, the finer FEM, then the adaptive runs."""
    return {case: {f"FEM {where['fem_run']}": read_history(where["fem_dir"]),
                   fine_label(where): read_history(where["fine_dir"]),
                   **{f"adaptive {run}": read_history(path) for run, path in where["adaptive_dirs"].items()}}
            for case, where in cases.items()}


def mesh_states(adaptive_dir, count: int = 3) -> list[dict]:
    """``count`` saved states of an adaptive run for the mesh picture: before the peak (at half of
    it), at the saved increment nearest the peak, and the last."""
    from ifenn import run_files

    history = read_history(adaptive_dir)
    fields = f"{adaptive_dir}/{run_files.FIELDS}"
    saved = run_files.saved_increments(fields)
    force = np.abs(history.reaction_force.to_numpy())
    k_peak = int(np.argmax(force))
    rising = np.nonzero(force[:k_peak + 1] >= 0.5 * force[k_peak])[0]
    wanted = [int(history.increment.iloc[rising[0]]) if rising.size else saved[0], int(history.increment.iloc[k_peak]), saved[-1]]
    chosen = sorted({min(saved, key=lambda s, w=w: abs(s - w)) for w in wanted[:count]})
    return run_files.read_states(fields, chosen, keys=("phase_field_gp", "leaf_level"))


def tree_maker(spec: dict):
    """leaf_level -> the Quadtree of an adaptive run's mesh (for pictures)."""
    from ifenn.adaptive.quadtree import Quadtree, pad
    from ifenn.adaptive.run import MeshSettings, fine_layout
    from ifenn.pixels import PixelGrid

    grid, settings = PixelGrid.for_scene(spec["scene"]), MeshSettings.from_spec(spec)
    h_fine = grid.h_px * settings.pixels_per_fine_cell
    levels, shape, removed = fine_layout(spec["scene"], grid, settings)

    def make(leaf_level: np.ndarray) -> Quadtree:   # saved on the scene's fine grid; built on the padded one
        return Quadtree((grid.x0, grid.y0), h_fine, levels, pad(np.asarray(leaf_level), shape, levels), removed=removed)

    return make
