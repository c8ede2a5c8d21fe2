"""How fast this machine is, in the unit the workflow spends most in: one direct solve of the
paper's snt1 displacement matrix (200 x 200 Q1 elements, 80,922 dofs, phi = 0) by MUMPS's
Cholesky, factorisation and solve, one core.

Machines differ up to ~3x: seconds measured on different machines compare only after scaling by
this number. Run it before timing the paper DAG and quote it beside the DAG's time.

A DAG runs two jobs at once, and two jobs on a machine's two "cores" may slow each other (shared
caches and memory bandwidth, or two hyperthreads of one core): ``--copies 2`` runs the measurement
in two processes at once and prints both, which says how a machine serves the DAG's condition.
The second number, one apply of the default preset's kept block Cholesky factor (memory-bound
triangular solves), is the better unit for the FEM and IFENN runs: a machine that factored 1.4x
slower than the reference below (0.191 s) applied 3.8x slower (25.9 ms against 6.9 ms; two copies
at once 29.0 / 26.5 ms), and its paper DAG's snt3-II pair took 2.4x as long (1,314 s against 546 s).

    .venv/bin/python benchmarks/machine_speed.py [--repeat N] [--copies 2] [--out results/benchmarks/machine_speed.json]

The workflow runs it alone at the start of every DAG (rule machine_speed, ``--out``), so a DAG's
benchmark files come with the machine they were measured on; ``python -m ifenn stage-times``
prints the two numbers beside the sums (:data:`REFERENCE`).
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from petsc4py import PETSc

from ifenn.config import REPO, fem_run_spec, load_config
from ifenn.io import atomic_path

#: the reference machine: a 2-core machine whose MUMPS factor + solve of snt1 takes 0.14 s and whose
#: kept-factor apply takes 6.9 ms; its paper DAG took 66.5 min on 2 cores
REFERENCE = {"mumps_factor_solve_s": 0.14, "kept_factor_apply_ms": 6.9}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="solves timed after a first one (default 5)")
    parser.add_argument("--copies", type=int, default=1, help="processes measuring at once, one core each (default 1)")
    parser.add_argument("--out", default=None, help="also write the two numbers here (JSON)")
    args = parser.parse_args()
    if args.copies > 1:
        with tempfile.TemporaryDirectory() as tmp:
            records = [Path(tmp) / f"copy{i}.json" for i in range(args.copies)]
            copies = [subprocess.Popen([sys.executable, __file__, "--repeat", str(args.repeat), "--out", str(record)],
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for record in records]
            for copy in copies:
                copy.wait()
            measured = [json.loads(record.read_text()) for record in records]
        solves = [m["mumps_factor_solve_s"] for m in measured]
        applies = [m["kept_factor_apply_ms"] for m in measured]
        print(f"{args.copies} copies at once, one core each: MUMPS factor + solve {', '.join(f'{m:.3f}' for m in solves)} s, "
              f"kept-factor apply {', '.join(f'{m:.1f}' for m in applies)} ms (run with --copies 1 for the machine alone)")
        return 0
    import dolfinx.fem.petsc as fem_petsc

    from ifenn.fem.mesh import build_mesh, read_dolfinx_mesh, write_mesh
    from ifenn.fem.problem import FractureProblem

    config = load_config(REPO / "config" / "config.yaml")
    spec = fem_run_spec(config, "snt1-II")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "snt1.xdmf"
        write_mesh(build_mesh(spec["scene"]), path)
        problem = FractureProblem(read_dolfinx_mesh(path), spec["scene"], spec["material"],
                                  config["solver"]["linear_solver_presets"]["direct"])
    A = fem_petsc.assemble_matrix(problem.equilibrium_form, bcs=problem.bcs)
    A.assemble()
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    ksp.getPC().setType(PETSc.PC.Type.CHOLESKY)
    ksp.getPC().setFactorSolverType("mumps")
    ksp.setOperators(A)
    b, x = A.createVecs()
    b.set(1.0)
    seconds = []
    for _ in range(args.repeat + 1):
        A.scale(2.0)   # new values: a numeric factorisation each time, as in a run
        A.scale(0.5)
        started = time.perf_counter()
        ksp.solve(b, x)
        seconds.append(time.perf_counter() - started)
    print(f"snt1 displacement matrix ({A.getSize()[0]:,} dofs), MUMPS Cholesky factor + solve, one core: "
          f"median {np.median(seconds[1:]):.3f} s over {args.repeat} (first, with the analysis: {seconds[0]:.3f} s); "
          f"the reference machine: {REFERENCE['mumps_factor_solve_s']} s")
    # the unit of the default preset (cholesky-reuse): one apply of the kept block Cholesky factor,
    # a CG iteration's preconditioner (memory-bound triangular solves)
    from ifenn.fem.factor import NestedDissectionCholesky

    baij = A.convert(PETSc.Mat.Type.BAIJ)
    pc = PETSc.PC().createPython(NestedDissectionCholesky(), PETSc.COMM_SELF)
    pc.setOperators(baij)
    pc.setUp()
    applies = []
    for _ in range(20 * args.repeat):
        started = time.perf_counter()
        pc.apply(b, x)
        applies.append(time.perf_counter() - started)
    print(f"the kept block Cholesky factor (cholesky-reuse) of the same matrix: one apply median {1e3 * np.median(applies):.1f} ms "
          f"(the reference machine: {REFERENCE['kept_factor_apply_ms']} ms)")
    if args.out:
        record = {"mumps_factor_solve_s": round(float(np.median(seconds[1:])), 4),
                  "kept_factor_apply_ms": round(1e3 * float(np.median(applies)), 2), "dofs": A.getSize()[0],
                  "repeat": args.repeat, "date": time.strftime("%Y-%m-%d", time.gmtime()), "host": platform.node(), "machine": platform.machine(),
                  "reference": {**REFERENCE, "what": "a 2-core machine, MUMPS factor 0.14 s, kept-factor apply 6.9 ms (its paper DAG: 66.5 min on 2 cores)"}}
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(args.out) as tmp:
            Path(tmp).write_text(json.dumps(record, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
