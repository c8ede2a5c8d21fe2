"""The whole increment, FEM against IFENN, with each displacement solver: one process,
one core, the propagation stage of snt1-II/snt2-II/snt3-II (config 'increment_benchmark').

Every (method, solver) pair restarts from the same saved FEM state (the switch-over increment of
the FEM run's fields.h5) and takes the same loads. The pairs advance in turn, one increment each
(A, B, C, ..., A, B, C, ...), so a load on the machine that comes and goes falls on all of them
alike: compare the rows of one run as ratios, not their seconds across runs or machines.

Methods (METHODS: name -> phase-field step factory; a new method is one more entry): ``fem``
(the Q1 phase-field solve), ``ifenn`` (the PICNN on the process zone, ``inference:
process_zone``, unchecked) and ``ifenn-verified`` (the run's verified step: the process-zone
prediction checked by the pixel equation and corrected where it fails). Solvers: the config's
``solvers`` map, a column label -> a linear-solver preset (``gamg`` -> ``iterative``, today's
default; ``direct``; ``gamg-reuse``).

Columns (one row per run, method, solver): the mean seconds per increment of the displacement
solve (assembly included), of the phase-field step and of the whole increment; and
force_rel_error_vs_direct, the largest |F - F_direct| over the increments, where F_direct is the
same method's force with the direct solver, divided by the FEM run's peak force. Then the
increments, the mean Krylov iterations of the displacement solve and the preconditioner refreshes
(the kept-preconditioner solver only).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/increment_speed.py [--increments N] [--out CSV]
"""

from __future__ import annotations

import argparse
import copy
import json
import logging
import tempfile
import time
from pathlib import Path

import pandas as pd

from ifenn.config import REPO, ifenn_run_spec, load_config

COLUMNS = ["run", "method", "displacement_solver", "t_displacement_s", "t_phase_field_s", "t_increment_s",
           "force_rel_error_vs_direct", "increments", "displacement_iterations", "preconditioner_refreshes"]


def fem_step(problem, spec, model_path):
    from ifenn.fem.phase_field import FEMPhaseField

    return FEMPhaseField(problem, spec["petsc"]["phase_field"])


def ifenn_process_zone_step(problem, spec, model_path):
    """The PICNN on the process zone, unchecked (the run's smoothing and cap)."""
    from ifenn.hybrid.runs import pixel_phase_field

    spec = {**spec, "inference": "process_zone", "predictor": "picnn", "evaluation": "orbit",
            "verification": {**(spec.get("verification") or {}), "enabled": False}}
    return pixel_phase_field(spec, problem, model_path)


def ifenn_verified_step(problem, spec, model_path):
    """The verified IFENN step of the run (its ``verification`` settings; the run must be a verified one)."""
    from ifenn.hybrid.runs import pixel_phase_field

    if not (spec.get("verification") or {}).get("enabled"):
        raise ValueError(f"method 'ifenn-verified' needs a verified IFENN run (verification.enabled); {spec['name']!r} is not one")
    return pixel_phase_field(spec, problem, model_path)


#: method -> factory(problem, spec, model path) of its phase-field step
METHODS = {"fem": fem_step, "ifenn": ifenn_process_zone_step, "ifenn-verified": ifenn_verified_step}


class Case:
    """One (method, solver) pair: a staggered run from the saved switch-over state, advanced
    one increment at a time. Uses StaggeredRun's own increment (the workflow's code path)."""

    def __init__(self, spec, domain, method, solver, start, model_path, work: Path):
        from ifenn.fem.problem import FractureProblem
        from ifenn.fem.solver import StaggeredRun

        self.method, self.solver = method, solver
        self.problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"])
        step = METHODS[method](self.problem, spec, model_path)
        self.run = StaggeredRun(self.problem, step, spec, work / f"{spec['name']}-{method}-{solver}", progress=False,
                                start=start, row_constants={"hybrid_active": int(method != "fem")})
        self.last = self.run._resume()
        self.u_previous = self.run.rows[-1]["u"]
        self.rows: list[dict] = []
        self.iterations: list[int] = []

    def advance(self) -> None:
        increment = self.last + 1
        u = self.run.loads.next_load(increment, self.u_previous)
        row = self.run.solve_increment(increment, u, self.u_previous)
        self.rows.append(row)
        self.iterations.append(self.problem.displacement_iterations)
        self.last, self.u_previous = increment, row["u"]


def increment_speed(specs: list[dict], solvers: dict[str, tuple[str, dict]], methods: list[str], increments: int,
                    model_path: str | Path, results: str | Path = "results") -> pd.DataFrame:
    """One row per (run, method, solver); ``specs``: IFENN run specs with process-zone settings
    (their FEM runs give the start state, the mesh and the peak force); ``solvers``: column
    label -> (preset name, preset: its PETSc options and displacement_reuse)."""
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.hybrid.runs import switch_state

    results = Path(results)
    table = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            spec = {**spec, "save_fields": [], "checkpoint_every": 10**6}
            fem_dir = results / "fem" / spec["fem_run"]
            switch, state, rows = switch_state(fem_dir)
            if switch < 0:
                raise ValueError(f"FEM run {spec['fem_run']} never reached the switch-over: no propagation stage to time")
            spec["load"] = spec["load"][: switch + increments]
            peak = pd.read_csv(fem_dir / "history.csv").reaction_force.abs().max()
            domain = read_dolfinx_mesh(results / "mesh" / f"{spec['scene_name']}.xdmf")
            cases = []
            for method in methods:
                for label, (preset, options) in solvers.items():
                    case_spec = copy.deepcopy(spec)
                    case_spec.update(name=f"{spec['fem_run']}-{method}-{label}", linear_solvers=preset, petsc=options)
                    start = {"increment": switch, "state": state, "rows": rows}
                    cases.append(Case(case_spec, domain, method, label, start, model_path, Path(tmp)))
            n = len(spec["load"]) - switch
            started = time.perf_counter()
            for k in range(n):  # interleaved: every case takes increment k before any takes k + 1
                for case in cases:
                    case.advance()
                print(f"{spec['fem_run']}: increment {k + 1}/{n} ({time.perf_counter() - started:.0f} s)", flush=True)
            direct = {c.method: pd.DataFrame(c.rows).reaction_force.to_numpy() for c in cases if c.solver == "direct"}
            for case in cases:
                history = pd.DataFrame(case.rows)
                force = history.reaction_force.to_numpy()
                error = float(abs(force - direct[case.method]).max() / peak) if case.method in direct else float("nan")
                reuse = case.problem.reuse
                table.append({"run": spec["fem_run"], "method": case.method, "displacement_solver": case.solver,
                              "t_displacement_s": history.t_displacement_s.mean(), "t_phase_field_s": history.t_phase_field_s.mean(),
                              "t_increment_s": history.t_increment_s.mean(), "force_rel_error_vs_direct": error,
                              "increments": len(history), "displacement_iterations": sum(case.iterations) / len(case.iterations),
                              "preconditioner_refreshes": reuse.refreshes if reuse else 0})
            del cases
    return pd.DataFrame(table, columns=COLUMNS)


def ratios(table: pd.DataFrame, solver: str) -> pd.DataFrame:
    """Per run: gamg / ``solver`` displacement time (every method), and FEM / each IFENN method's
    increment time with ``solver``."""
    t = table.set_index(["run", "method", "displacement_solver"])
    out = []
    for run in table.run.unique():
        row = {"run": run}
        for method in table.method.unique():
            row[f"{method}_displacement_gamg_over_{solver}"] = t.loc[(run, method, "gamg"), "t_displacement_s"] / t.loc[(run, method, solver), "t_displacement_s"]
        if "fem" in set(table.method):
            for method in sorted(set(table.method) - {"fem"}):
                row[f"increment_fem_over_{method}_{solver}"] = (t.loc[(run, "fem", solver), "t_increment_s"]
                                                                / t.loc[(run, method, solver), "t_increment_s"])
        out.append(row)
    return pd.DataFrame(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", nargs="+", default=[str(REPO / "config" / "config.yaml")])
    parser.add_argument("--model", default="results/picnn/model.pt")
    parser.add_argument("--results", default="results", help="folder with fem/ and mesh/ of the workflow")
    parser.add_argument("--runs", nargs="+", default=None, help="IFENN runs; default: increment_benchmark.runs")
    parser.add_argument("--specs", nargs="+", default=None, help="IFENN run specs (results/ifenn/RUN/spec.json) instead of --runs")
    parser.add_argument("--solvers", default=None, help="JSON {label: [preset, options]}; default: increment_benchmark.solvers of --config")
    parser.add_argument("--new-solver", default=None, help="label of the solver whose ratios are printed")
    parser.add_argument("--process-zone", default=None, help="JSON of the process-zone settings; default: ifenn.process_zone of --config")
    parser.add_argument("--increments", type=int, default=None, help="default: increment_benchmark.increments")
    parser.add_argument("--methods", nargs="+", default=None, choices=list(METHODS), help="default: increment_benchmark.methods")
    parser.add_argument("--out", default="results/benchmarks/increment_speed.csv")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    for noisy in ("ffcx", "UFL", "root", "compilers", "ifenn"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    import torch

    torch.set_num_threads(1)
    config = load_config(*args.config)
    setup = config["increment_benchmark"]
    if args.specs:
        specs = [json.loads(Path(path).read_text()) for path in args.specs]
    else:
        specs = [ifenn_run_spec(config, run) for run in args.runs or setup["runs"]]
    zone = json.loads(args.process_zone) if args.process_zone else config["ifenn"]["process_zone"]
    for spec in specs:   # the process-zone settings, where a run does not carry them itself
        spec["process_zone"] = spec.get("process_zone") or zone
    presets = config["solver"]["linear_solver_presets"]
    solvers = json.loads(args.solvers) if args.solvers else {label: (name, presets[name]) for label, name in setup["solvers"].items()}
    new_solver = args.new_solver or setup["new_solver"]
    methods = args.methods or setup["methods"]
    table = increment_speed(specs, solvers, methods, args.increments or setup["increments"], args.model, args.results)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    with pd.option_context("display.width", 220, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print("\nSeconds per increment (mean over the increments after the switch-over), interleaved in one process:")
        print(table.to_string(index=False))
        print(f"\nRatios (same process, same states):\n{ratios(table, new_solver).to_string(index=False)}")
    print(json.dumps({"written": args.out}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
