"""Stability where the methods fail: a sweep of load step, lc/h and IFENN options on
a small single-notch scene, both methods, each cell classified from its metrics.

Cells: FEM and IFENN runs on the sweep scene (config 'stability.scene') with
  - the load steps 'stability.steps' at the scene's own lc/h,
  - the lc/h values 'stability.lc_over_h' at 'stability.step' (elements scaled, lc and the
    network unchanged: the PICNN stays the one trained at the paper's lc/h),
  - the IFENN option variants 'stability.ifenn_variants' at the scene's lc/h and 'step'.
A cell is compared with a reference: FEM cells with FEM at the finest load step (load-step
panel) or on the finest mesh (lc/h panel), IFENN cells with FEM on the same scene and step.

Labels, checked in this order (the first that applies):
  diverged        the solver failed (ifenn.errors.SolverDivergedError: a Krylov failure, the pixel
                  correction's iterations exhausted, a non-finite result); any other error stops
                  the job with its message (a CUDA out-of-memory is not a physical result)
  no load drop    final force > final_force_max x the cell's own peak
  crack path wrong  IoU of the final crack set (phi >= 0.5) with the reference's < iou_min
  peak off        |peak force / reference peak - 1| > peak_error_max
  ok
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from ifenn import materials, run_files
from ifenn.config import fem_run_spec, ifenn_run_spec
from ifenn.errors import SolverDivergedError

LABELS = ("ok", "peak off", "crack path wrong", "no load drop", "diverged")


def _tag(value: float) -> str:
    """Compact exact label of a step: 2.5e-06 -> '2.5e-6', 1e-05 -> '1e-5'."""
    mantissa, exponent = f"{value:.6e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


def cell_name(method: str, lc_over_h: float, step: float, variant: str = "base") -> str:
    name = f"{method}_lch{lc_over_h:g}_du{_tag(step)}"
    return name if method == "fem" or variant == "base" else f"{name}_{variant}"


def cells(config: dict) -> dict:
    """Every cell of the sweep: name -> {'method', 'lc_over_h', 'step', 'variant', 'spec',
    'fem_cell' (IFENN: the FEM cell it continues)}."""
    sweep = config["stability"]
    scene = config["scenes"][sweep["scene"]]
    base_lch = round(materials.lc_over_h(config["material"], scene), 6)
    points = {(base_lch, s) for s in sweep["steps"]} | {(float(L), sweep["step"]) for L in sweep["lc_over_h"]}
    out = {}
    for lch, step in sorted(points):
        variants = {"base": {}}
        if lch == base_lch and step == sweep["step"]:
            variants.update(sweep["ifenn_variants"])
        for method in ("fem", "ifenn"):
            for variant, options in (variants.items() if method == "ifenn" else [("base", {})]):
                name = cell_name(method, lch, step, variant)
                out[name] = {"method": method, "lc_over_h": lch, "step": step, "variant": variant,
                             "spec": _cell_spec(config, name, scene, lch, step, method, options),
                             "fem_cell": cell_name("fem", lch, step)}
    return out


def _cell_spec(config: dict, name: str, scene: dict, lc_over_h: float, step: float, method: str, options: dict) -> dict:
    sweep = config["stability"]
    cfg = copy.deepcopy(config)
    width, height = (scene["domain"]["x"][1] - scene["domain"]["x"][0]), (scene["domain"]["y"][1] - scene["domain"]["y"][0])
    h = materials.scene_material(config["material"], scene)["lc"] / lc_over_h   # the scene's own lc, kept
    cfg["scenes"] = {"cell": {**scene, "elements": [int(round(width / h)), int(round(height / h))]}}
    cfg["schedules"] = {"cell": [{"increments": int(round(sweep["u_end"] / step)), "step": step}]}
    cfg["fem_runs"] = {"cell": {"scene": "cell", "schedule": "cell"}}
    cfg["ifenn_runs"] = {"cell": {"fem_run": "cell", **options}}
    cfg["picnn"] = {**cfg["picnn"], "training_run": "cell", "training_increments": []}
    cfg["figures"] = {**cfg["figures"], "views_3d": None}
    spec = fem_run_spec(cfg, "cell") if method == "fem" else ifenn_run_spec(cfg, "cell")
    spec["name"] = name
    spec["save_fields"] = []  # the last increment (and the switch-over) are always saved
    return spec


# ------------------------------------------------------------------ classification
def classify(metrics: dict, thresholds: dict) -> str:
    """The label of a cell from its metrics (keys: status, peak_force, final_force,
    reference_peak_force, crack_iou); see the module docstring for the order."""
    if metrics["status"] != "ok" or not np.isfinite(metrics.get("peak_force", np.nan)):
        return "diverged"
    if metrics["final_force"] > thresholds["final_force_max"] * metrics["peak_force"]:
        return "no load drop"
    if metrics["crack_iou"] < thresholds["iou_min"]:
        return "crack path wrong"
    if abs(metrics["peak_force"] / metrics["reference_peak_force"] - 1.0) > thresholds["peak_error_max"]:
        return "peak off"
    return "ok"


def resample(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-pixel resampling of an image covering the same domain onto ``shape``."""
    rows = ((np.arange(shape[0]) + 0.5) * image.shape[0] / shape[0]).astype(int)
    cols = ((np.arange(shape[1]) + 0.5) * image.shape[1] / shape[1]).astype(int)
    return image[np.ix_(rows, cols)]


def cell_metrics(cell_dir: str | Path, reference_dir: str | Path) -> dict:
    """Peak and final force, crack IoU of the final phase field against the reference
    (both resampled to the coarser pixel grid) and the reference's peak force."""
    from ifenn.studies.tables.metrics import crack_iou, force_curve_error

    cell_dir, reference_dir = Path(cell_dir), Path(reference_dir)
    status = run_files.read_status(cell_dir)
    out = {"status": status["status"], "error": status.get("error", ""), "wall_s": status.get("wall_s", np.nan)}
    ref_status = run_files.read_status(reference_dir)
    if status["status"] != "ok" or ref_status["status"] != "ok":
        if status["status"] == "ok":
            out["status"] = "reference failed"
        return out
    history, reference = run_files.read_history(cell_dir), run_files.read_history(reference_dir)

    def final_phi(path):
        fields = path / run_files.FIELDS
        return run_files.read_states(fields, run_files.saved_increments(fields)[-1:], keys=("phase_field_gp",))[0]["phase_field_gp"]

    a, b = final_phi(cell_dir), final_phi(reference_dir)
    shape = min(a.shape, b.shape)
    out.update(peak_force=float(history.reaction_force.max()), final_force=float(history.reaction_force.iloc[-1]),
               reference_peak_force=float(reference.reaction_force.max()),
               crack_iou=crack_iou(resample(a, shape), resample(b, shape)),
               force_l2_rel_error=force_curve_error(history.u.to_numpy(), history.reaction_force.to_numpy(),
                                                    reference.u.to_numpy(), reference.reaction_force.to_numpy()),
               increments=len(history), wall_s=status.get("wall_s", np.nan))
    return out


def table_rows(config: dict) -> list[dict]:
    """One row per panel entry: (panel, value, method) -> the cell and its reference."""
    sweep = config["stability"]
    base_lch = round(materials.lc_over_h(config["material"], config["scenes"][sweep["scene"]]), 6)
    finest_step, finest_lch = min(sweep["steps"]), max(float(v) for v in sweep["lc_over_h"])
    rows = []
    for step in sweep["steps"]:
        for method in ("fem", "ifenn"):
            ref = cell_name("fem", base_lch, finest_step) if method == "fem" else cell_name("fem", base_lch, step)
            rows.append({"panel": "load step", "value": _tag(step), "method": method,
                         "cell": cell_name(method, base_lch, step), "reference": ref})
    for lch in sweep["lc_over_h"]:
        for method in ("fem", "ifenn"):
            ref = cell_name("fem", finest_lch, sweep["step"]) if method == "fem" else cell_name("fem", float(lch), sweep["step"])
            rows.append({"panel": "lc/h", "value": f"{float(lch):g}", "method": method,
                         "cell": cell_name(method, float(lch), sweep["step"]), "reference": ref})
    for variant in ["base", *sweep["ifenn_variants"]]:
        rows.append({"panel": "IFENN option", "value": variant, "method": "ifenn",
                     "cell": cell_name("ifenn", base_lch, sweep["step"], variant), "reference": cell_name("fem", base_lch, sweep["step"])})
    return rows


def stability_table(config: dict, cell_root: str | Path):
    """The sweep's CSV: per panel entry the metrics and the label."""
    import pandas as pd

    rows = []
    for row in table_rows(config):
        metrics = cell_metrics(Path(cell_root) / row["cell"], Path(cell_root) / row["reference"])
        rows.append({**row, **metrics, "label": classify(metrics, config["stability"]["thresholds"])})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ running one cell
def run_cell(spec: dict, out_dir: str | Path, fem_dir: str | Path | None = None, model: str | Path | None = None,
             device="auto") -> dict:
    """Run one cell (FEM, or IFENN continuing ``fem_dir``, its network on ``device``); never raises
    for a solver failure: status.json says 'ok', 'diverged' (with the error) or 'not started'.
    A bad device setting is refused before the cell starts."""
    import time

    from ifenn.device import network_device
    from ifenn.fem.mesh import build_mesh, write_mesh

    device = network_device(spec, device)   # None for FEM cells and the exact pixel solve
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for stale in (run_files.STATUS, run_files.HISTORY, run_files.FIELDS, "paraview.xdmf", "paraview.h5", run_files.PROVENANCE):
        (out_dir / stale).unlink(missing_ok=True)
    started = time.perf_counter()
    status = {"status": "ok"}
    try:
        if fem_dir is None:
            from ifenn.fem.solver import run_fem

            write_mesh(build_mesh(spec["scene"]), out_dir / "mesh.xdmf")
            run_fem(spec, out_dir / "mesh.xdmf", out_dir, progress=False)
        else:
            from ifenn.hybrid.runs import run_ifenn

            fem_status = run_files.read_status(fem_dir)
            if fem_status["status"] != "ok":
                status = {"status": "diverged", "error": f"its FEM cell failed: {fem_status.get('error', '')}"}
            else:
                run_ifenn(spec, Path(fem_dir) / "mesh.xdmf", fem_dir, model, out_dir, progress=False, device=device)
    except SolverDivergedError as error:   # the solver's own failure; any other error stops the job
        status = {"status": "diverged", "error": str(error)[:500]}
    status["wall_s"] = time.perf_counter() - started
    run_files.write_status(out_dir, status)
    return status
