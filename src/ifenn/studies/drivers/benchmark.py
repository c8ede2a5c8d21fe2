"""Phase-field step cost, FEM against IFENN (full image and process zone), on the same core
in the same process: snt1/snt2/snt3 (the mesh study's runs, schedule II), a fixed number of
increments of crack propagation from each FEM run's switch-over state.

IFENN methods: the full image with the network's convolutions (torch conv2d, the paper's
step), the full image with the same network evaluated as orbit sums + products (ifenn.network.orbit,
in the compiled kernel where it builds: the column network_kernel says which ran), and the
process zone (orbit evaluation).

For each scene and method the run restarts from the same FEM state and takes the same loads;
only the phase-field step differs. t_phase_field_s is everything that step does: for FEM the
assembly and solve (and the evaluation at the Gauss points), for IFENN the Gauss point ->
pixel conversion, capping, inference, smoothing, back-projection and irreversibility.

Every IFENN method runs once per device of ``devices`` (the CPU, and CUDA where torch sees one:
column ``device``, by name; on a GPU the network runs as its convolutions, ``network_kernel``
conv2d). FEM runs once, on PETSc (``device`` cpu).
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import pandas as pd

#: method -> overrides of the IFENN run spec (None: the FEM step). The verified methods check
#: every prediction by the pixel equation and correct it (ifenn.hybrid.verification): with the configured
#: warm start (ifenn.verification), with the network's prediction wherever it changed on the process
#: zone's tolerance (the first verified step), or with the last verified phi only (no network: what the
#: network saves).
_VERIFIED = {"inference": "process_zone", "evaluation": "orbit", "smoothing_sigma": None, "irreversible": False}
METHODS = {"fem": None, "ifenn_full_convolution": {"inference": "full", "evaluation": "convolution"},
           "ifenn_full": {"inference": "full", "evaluation": "orbit"},
           "ifenn_process_zone": {"inference": "process_zone", "evaluation": "orbit"},
           "ifenn_verified": {**_VERIFIED, "verification": {}},
           "ifenn_verified_network": {**_VERIFIED, "verification": {"warm_start": "network", "network_tolerance": None}},
           "ifenn_verified_nonet": {**_VERIFIED, "verification": {"warm_start": "previous"}}}


def _run(spec: dict, mesh_path: Path, fem_dir: Path, model_path: Path, method: str, increments: int, work: Path,
         device=None) -> pd.DataFrame:
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.fem.phase_field import FEMPhaseField
    from ifenn.fem.problem import FractureProblem
    from ifenn.fem.solver import StaggeredRun
    from ifenn.hybrid.runs import pixel_phase_field, switch_state

    switch, state, rows = switch_state(fem_dir)
    spec = copy.deepcopy(spec)
    spec.update(name=f"{spec['name']}-{method}-{getattr(device, 'type', 'cpu')}", load=spec["load"][: switch + increments], save_fields=[], checkpoint_every=10**6)
    overrides = copy.deepcopy(METHODS[method])
    if overrides:
        if "verification" in overrides:
            overrides["verification"] = {**spec["verification"], **overrides["verification"], "enabled": True}
        else:
            spec.pop("verification", None)
        spec.update(overrides)
    domain = read_dolfinx_mesh(mesh_path)
    problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"])
    kernel = ""
    if method == "fem":
        step = FEMPhaseField(problem, spec["petsc"]["phase_field"])
    else:
        step = pixel_phase_field(spec, problem, model_path, device=device)
        kernel = step.inference.kernel
    start = {"increment": switch, "state": state, "rows": rows}
    run = StaggeredRun(problem, step, spec, work / spec["name"], progress=False, start=start,
                       row_constants={"hybrid_active": int(method != "fem")})
    history = pd.DataFrame(run.run())
    return history[history.increment > switch].assign(network_kernel=kernel)


def phase_field_speed(specs: list[dict], inputs: dict[str, dict], process_zone: dict, model_path: str | Path, increments: int = 40,
                      verification: dict | None = None, devices=None) -> pd.DataFrame:
    """One row per (IFENN run spec, method): mean seconds per increment of the displacement
    solve, the phase-field step and the increment, the fraction of pixels the network
    evaluated, and the phase-field step's speed-up over FEM's. ``process_zone``: the settings
    of the process-zone method (config 'ifenn.process_zone'); ``verification``: those of the
    verified methods (config 'ifenn.verification'; ``enabled`` is set by the method).
    ``inputs``: per run name, its scene's ``mesh`` (XDMF) and its FEM run's ``fem_dir``; ``devices``:
    where the IFENN methods run (default :func:`ifenn.device.default_devices`)."""
    from ifenn.device import default_devices, describe

    devices = default_devices() if devices is None else devices
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            spec = {**spec, "process_zone": spec.get("process_zone") or process_zone,
                    "verification": spec.get("verification") or verification or {}}
            fem_dir, mesh = Path(inputs[spec["name"]]["fem_dir"]), Path(inputs[spec["name"]]["mesh"])
            for method, device in [(m, d) for m in METHODS for d in ([None] if METHODS[m] is None else devices)]:
                history = _run(spec, mesh, fem_dir, Path(model_path), method, increments, Path(tmp), device)
                nx, ny = spec["scene"]["elements"]
                rows.append({"run": spec["name"], "elements": f"{nx}x{ny}", "pixels": f"{2 * nx}x{2 * ny}", "method": method,
                             "device": "cpu" if device is None else describe(device),
                             "network_kernel": history.network_kernel.iloc[0],
                             "increments": len(history),
                             "t_displacement_s": history.t_displacement_s.mean(),
                             "t_phase_field_s": history.t_phase_field_s.mean(),
                             "t_phase_field_median_s": history.t_phase_field_s.median(),
                             "t_inference_s": history.t_inference_s.mean() if "t_inference_s" in history else 0.0,
                             "evaluated_fraction": history.evaluated_fraction.mean() if "evaluated_fraction" in history else 1.0,
                             "t_increment_s": history.t_increment_s.mean(),
                             "t_verify_s": history.t_verify_s.mean() if "t_verify_s" in history else 0.0,
                             "verify_corrected_fraction": (history.verify_corrected_fraction.mean()
                                                           if "verify_corrected_fraction" in history else 0.0),
                             "verify_residual_after_max": (history.verify_residual_after.max()
                                                           if "verify_residual_after" in history else float("nan")),
                             "verify_solve_work": history.verify_solve_work.mean() if "verify_solve_work" in history else 0.0,
                             "final_force": history.reaction_force.iloc[-1]})
    table = pd.DataFrame(rows)
    fem = table[table.method == "fem"].set_index("run").t_phase_field_s
    table["phase_field_speedup_vs_fem"] = table.run.map(fem) / table.t_phase_field_s
    return table
