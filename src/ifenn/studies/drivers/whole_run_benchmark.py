"""The phase-field step over the whole run: FEM against whole-path IFENN (the verified
step from the first increment), on the same core in the same process.

For each whole-path run (config 'whole_run_benchmark.runs', ``switch_over: start``) two runs
of the same scene and schedule are set up from the initial state: FEM (the Q1 phase-field
solve) and the run's IFENN step. Their increments are interleaved (FEM then IFENN on odd
increments, IFENN then FEM on even ones), so both see the same machine load over the run;
only the phase-field step differs in what they compute. ``t_phase_field_s`` is everything
the step does (FEM: assembly, solve, evaluation at the Gauss points; IFENN: Gauss points ->
pixels, cap, network, check and correction, pixels -> Gauss points). Fixed schedules only.
The IFENN run is repeated on each device of ``devices`` (the CPU, and CUDA where torch sees one:
column ``device``; FEM's row says cpu, PETSc's); all runs are interleaved, in rotating order.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from ifenn.io import progress_bar

#: columns of the per-increment table (those a method lacks are NaN)
INCREMENT_COLUMNS = ["increment", "u", "reaction_force", "phi_max", "t_displacement_s", "t_phase_field_s", "t_increment_s",
                     "t_inference_s", "t_verify_s", "verify_corrected_fraction", "verify_solve_work"]


def _runs(spec: dict, mesh_path: Path, model_path: Path, work: Path, devices) -> dict:
    """(method, device) -> StaggeredRun at the initial state: the FEM run and the whole-path IFENN
    run of ``spec`` on each of ``devices``."""
    from ifenn.device import describe
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.fem.phase_field import FEMPhaseField
    from ifenn.fem.problem import FractureProblem
    from ifenn.fem.solver import StaggeredRun
    from ifenn.hybrid.runs import pixel_phase_field

    runs = {}
    for method, device in [("fem", None)] + [("ifenn", device) for device in devices]:
        domain = read_dolfinx_mesh(mesh_path)
        problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"])
        if method == "fem":
            step = FEMPhaseField(problem, spec["petsc"]["phase_field"])
        else:
            step = pixel_phase_field(spec, problem, model_path, device=device)
        name = "cpu" if device is None else describe(device)
        run_spec = {**copy.deepcopy(spec), "name": f"{spec['name']}-{method}-{name.split()[0]}", "save_fields": [], "checkpoint_every": 10**9}
        runs[method, name] = StaggeredRun(problem, step, run_spec, work / run_spec["name"], progress=False,
                                          row_constants={"hybrid_active": 1} if method == "ifenn" else None)
    return runs


def interleave(runs: dict, progress=None) -> None:
    """Advance each :class:`ifenn.fem.solver.StaggeredRun` of ``runs`` one increment per turn, in
    rotating order (turn k starts with the k-th run), until all are done: every run sees the same
    machine load over its increments. ``progress``: a bar updated once per turn."""
    steps = {key: run.steps() for key, run in runs.items()}
    turn = 0
    while steps:
        keys = list(steps)
        for key in keys[turn % len(keys):] + keys[:turn % len(keys)]:
            if next(steps[key], None) is None:
                del steps[key]
        turn += 1
        if progress is not None:
            progress.update(1)


def whole_run_speed(specs: list[dict], inputs: dict[str, dict], model_path: str | Path,
                    increments: int | None = None, progress: bool = True, devices=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(summary, per-increment table), standalone (``benchmarks/whole_run_speed.py``; the workflow
    takes its rows from :func:`paired_whole_run`, which writes the runs too). ``specs``: whole-path
    IFENN run specs (``switch_over`` 'start', a fixed schedule); ``increments``: the first increments
    of each schedule (None: all).
    Summary, one row per (run, method): increments, total / mean / median phase-field seconds,
    the totals before FEM's phi-threshold increment (pre-nucleation) and from it on
    (propagation), displacement and increment totals, the final force, and FEM's phase-field
    total over the method's (``phase_field_speedup_vs_fem``, > 1 = faster than FEM). ``devices``:
    where the IFENN run is repeated (default :func:`ifenn.device.default_devices`)."""
    from ifenn.device import default_devices

    devices = default_devices() if devices is None else devices
    summary, per_increment = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            if spec.get("switch_over") != "start" or spec.get("load") is None:
                raise ValueError(f"run {spec['name']}: the whole-run benchmark needs switch_over 'start' and a fixed schedule")
            spec = {**spec, "load": spec["load"][:increments] if increments else spec["load"]}
            runs = _runs(spec, Path(inputs[spec["name"]]["mesh"]), Path(model_path), Path(tmp), devices)
            bar = progress_bar(total=len(spec["load"]), desc=f"{spec['name']} (FEM + IFENN)") if progress else None
            interleave(runs, bar)
            if bar is not None:
                bar.close()
            rows, frames = whole_run_rows(spec, {key: pd.DataFrame(run.rows) for key, run in runs.items()})
            summary += rows
            per_increment += frames
    return whole_run_tables(summary, per_increment)


def paired_whole_run(fem_spec: dict, ifenn_spec: dict, mesh_path: str | Path, model_path: str | Path, fem_dir: str | Path,
                     ifenn_dir: str | Path, device="auto", devices=None, increments: int | None = None,
                     progress: bool = True) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The FEM run ``fem_spec`` and the whole-path IFENN run ``ifenn_spec`` of the same scene,
    run in one process with their increments interleaved (rotating order, as
    :func:`whole_run_speed`), each writing its own run directory as :func:`ifenn.fem.solver.run_fem`
    and :func:`ifenn.hybrid.runs.run_ifenn` would (same files, locks, checkpoints: a killed job
    resumes both); their histories give the benchmark's tables, so the workflow computes these runs
    once. ``device``: where the IFENN run's network runs; the IFENN run is repeated, for the
    benchmark only, on each other device of ``devices`` (default: the CPU and CUDA where present).
    ``increments``: the tables count the first N increments (None: all). Any schedule, fixed or
    adaptive: each run advances one increment per turn until both are done."""
    import contextlib

    from ifenn.device import default_devices, describe, network_device
    from ifenn.fem.solver import fem_run
    from ifenn.hybrid.runs import ifenn_run
    from ifenn.run_files import exclusive_writer

    if ifenn_spec.get("switch_over") != "start":
        raise ValueError(f"run {ifenn_spec['name']}: a paired whole-path run needs switch_over 'start'")
    resolved = network_device(ifenn_spec, device)
    devices = default_devices() if devices is None else devices
    with contextlib.ExitStack() as stack, tempfile.TemporaryDirectory() as tmp:
        stack.enter_context(exclusive_writer(fem_dir))
        stack.enter_context(exclusive_writer(ifenn_dir))
        runs = {("fem", "cpu"): fem_run(fem_spec, mesh_path, fem_dir, progress=progress),
                ("ifenn", describe(resolved) if resolved is not None else "cpu"):
                    ifenn_run(ifenn_spec, mesh_path, None, model_path, ifenn_dir, progress=progress, device=resolved)}
        for other in devices:
            if resolved is not None and other != resolved:
                spec = {**copy.deepcopy(ifenn_spec), "save_fields": [], "checkpoint_every": 10**9}
                runs["ifenn", describe(other)] = ifenn_run(spec, mesh_path, None, model_path, Path(tmp) / describe(other).split()[0],
                                                           progress=False, device=other)
        interleave(runs)
        histories = {key: pd.DataFrame(run.rows).iloc[:increments] for key, run in runs.items()}
    return whole_run_tables(*whole_run_rows(ifenn_spec, histories))


def whole_run_rows(spec: dict, histories: dict) -> tuple[list[dict], list[pd.DataFrame]]:
    """The summary rows and per-increment frames of one whole-path run ``spec`` from the
    histories of its runs, ``(method, device) -> DataFrame`` (FEM's key ('fem', 'cpu'))."""
    summary, per_increment = [], []
    fem_history = histories["fem", "cpu"]
    over = fem_history.increment[fem_history.phi_max > spec["switch_phi_max"]]
    nucleation = int(over.iloc[0]) if len(over) else int(fem_history.increment.max()) + 1
    for (method, device), history in histories.items():
        frame = history.reindex(columns=INCREMENT_COLUMNS)
        per_increment.append(frame.assign(run=spec["name"], fem_run=spec["fem_run"], method=method, device=device))
        pre = history.increment < nucleation
        summary.append({"run": spec["name"], "fem_run": spec["fem_run"], "method": method, "device": device,
                        "elements": "x".join(map(str, spec["scene"]["elements"])), "increments": len(history),
                        "fem_switch_increment": nucleation,
                        "t_phase_field_total_s": history.t_phase_field_s.sum(),
                        "t_phase_field_mean_s": history.t_phase_field_s.mean(),
                        "t_phase_field_median_s": history.t_phase_field_s.median(),
                        "t_phase_field_pre_nucleation_s": history.t_phase_field_s[pre].sum(),
                        "t_phase_field_propagation_s": history.t_phase_field_s[~pre].sum(),
                        "t_displacement_total_s": history.t_displacement_s.sum(),
                        "t_increment_total_s": history.t_increment_s.sum(),
                        "verify_solve_work_mean": history.verify_solve_work.mean() if "verify_solve_work" in history else np.nan,
                        "final_force": history.reaction_force.iloc[-1],
                        "peak_force": history.reaction_force.abs().max()})
    return summary, per_increment


def whole_run_tables(summary: list[dict], per_increment: list[pd.DataFrame]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(summary, per-increment table) of :func:`whole_run_speed` from the rows of
    :func:`whole_run_rows`: adds the ratios to FEM of the same run."""
    table = pd.DataFrame(summary)
    fem = table[table.method == "fem"].set_index("run")
    for column, name in (("t_phase_field_total_s", "phase_field_speedup_vs_fem"),
                         ("t_phase_field_pre_nucleation_s", "pre_nucleation_speedup_vs_fem"),
                         ("t_phase_field_propagation_s", "propagation_speedup_vs_fem"),
                         ("t_increment_total_s", "increment_speedup_vs_fem")):
        table[name] = table.run.map(fem[column]) / table[column]
    increments_table = pd.concat(per_increment, ignore_index=True)
    lead = ["run", "fem_run", "method", "device"]
    return table, increments_table[lead + [c for c in increments_table.columns if c not in lead]]
