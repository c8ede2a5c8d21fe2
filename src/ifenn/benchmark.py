"""Phase-field step cost, FEM against IFENN (full image and process zone), on the same core
in the same process: snt1/snt2/snt3 (the mesh study's runs, schedule II), a fixed number of
increments of crack propagation from each FEM run's switch-over state.

IFENN methods: the full image with the network's convolutions (torch conv2d, the paper's
step), the full image with the same network evaluated as orbit sums + products (ifenn.orbit,
in the compiled kernel where it builds: the column network_kernel says which ran), and the
process zone (orbit evaluation).

For each scene and method the run restarts from the same FEM state and takes the same loads;
only the phase-field step differs. t_phase_field_s is everything that step does: for FEM the
assembly and solve (and the evaluation at the Gauss points), for IFENN the Gauss point ->
pixel conversion, capping, inference, smoothing, back-projection and irreversibility.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import pandas as pd

#: method -> (inference, evaluation) of the IFENN step (None: the FEM step)
METHODS = {"fem": None, "ifenn_full_convolution": ("full", "convolution"), "ifenn_full": ("full", "orbit"),
           "ifenn_process_zone": ("process_zone", "orbit")}


def _run(spec: dict, mesh_path: Path, fem_dir: Path, model_path: Path, method: str, increments: int, work: Path) -> pd.DataFrame:
    from .hybrid import make_inference, switch_state
    from .mesh import read_dolfinx_mesh
    from .phase_field_steps import FEMPhaseField, PixelPhaseField
    from .problem import FractureProblem
    from .solver import StaggeredRun

    switch, state, rows = switch_state(fem_dir)
    spec = copy.deepcopy(spec)
    spec.update(name=f"{spec['name']}-{method}", load=spec["load"][: switch + increments], save_fields=[], checkpoint_every=10**6)
    if METHODS[method]:
        spec.update(inference=METHODS[method][0], evaluation=METHODS[method][1])
    domain = read_dolfinx_mesh(mesh_path)
    problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"])
    kernel = ""
    if method == "fem":
        step = FEMPhaseField(problem, spec["petsc"]["phase_field"])
    else:
        inference = make_inference(spec, model_path, problem.pixels.h_px, problem.pixels.shape)
        kernel = inference.kernel
        step = PixelPhaseField(problem, inference, spec["predictor"], spec["history_cap"], spec["irreversible"])
    start = {"increment": switch, "state": state, "rows": rows}
    run = StaggeredRun(problem, step, spec, work / spec["name"], progress=False, start=start,
                       row_constants={"hybrid_active": int(method != "fem")})
    history = pd.DataFrame(run.run())
    return history[history.increment > switch].assign(network_kernel=kernel)


def phase_field_speed(specs: list[dict], process_zone: dict, model_path: str | Path, increments: int = 40,
                      results: str | Path = "results") -> pd.DataFrame:
    """One row per (IFENN run spec, method): mean seconds per increment of the displacement
    solve, the phase-field step and the increment, the fraction of pixels the network
    evaluated, and the phase-field step's speed-up over FEM's. ``process_zone``: the settings
    of the process-zone method (config 'ifenn.process_zone')."""
    results = Path(results)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            spec = {**spec, "process_zone": spec.get("process_zone") or process_zone}
            fem_dir = results / "fem" / spec["fem_run"]
            mesh = results / "mesh" / f"{spec['scene_name']}.xdmf"
            for method in METHODS:
                history = _run(spec, mesh, fem_dir, Path(model_path), method, increments, Path(tmp))
                nx, ny = spec["scene"]["elements"]
                rows.append({"run": spec["name"], "elements": f"{nx}x{ny}", "pixels": f"{2 * nx}x{2 * ny}", "method": method,
                             "network_kernel": history.network_kernel.iloc[0],
                             "increments": len(history),
                             "t_displacement_s": history.t_displacement_s.mean(),
                             "t_phase_field_s": history.t_phase_field_s.mean(),
                             "t_phase_field_median_s": history.t_phase_field_s.median(),
                             "t_inference_s": history.t_inference_s.mean() if "t_inference_s" in history else 0.0,
                             "evaluated_fraction": history.evaluated_fraction.mean() if "evaluated_fraction" in history else 1.0,
                             "t_increment_s": history.t_increment_s.mean(),
                             "final_force": history.reaction_force.iloc[-1]})
    table = pd.DataFrame(rows)
    fem = table[table.method == "fem"].set_index("run").t_phase_field_s
    table["phase_field_speedup_vs_fem"] = table.run.map(fem) / table.t_phase_field_s
    return table
