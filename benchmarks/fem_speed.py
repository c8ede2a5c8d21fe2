"""FEM cost per increment and step, snt1/snt2/snt3, serial and `mpirun -n 2`, plus the
force-curve error of the iterative solvers against a direct-solver run of snt1.

Every case is a real run of the workflow's solver (`python -m ifenn fem`) on the paper's
mesh with load schedule I (350 increments to u = 0.007: elastic loading, crack initiation
and propagation). Means exclude increment 1 (JIT compilation, preconditioner set-up).
Run on a quiet machine: the numbers are wall times.

    .venv/bin/python benchmarks/fem_speed.py [--increments N] [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from _cli import run_fem_spec

from ifenn.config import REPO, fem_run_spec, load_config
from ifenn.fem.mesh import build_mesh, write_mesh

STEPS = ["t_displacement_s", "t_phase_field_s", "t_history_s", "t_increment_s"]


def run_case(config, scene, preset, ranks, increments, work: Path) -> pd.DataFrame:
    spec = fem_run_spec(config, "snt1-I")
    spec.update(scene_name=scene, scene=config["scenes"][scene], name=f"{scene}-{preset}-n{ranks}",
                linear_solvers=preset, petsc=config["solver"]["linear_solver_presets"][preset],
                load=spec["load"][:increments], save_fields=[], checkpoint_every=10**6)
    mesh = work / f"{scene}.xdmf"
    if not mesh.exists():
        write_mesh(build_mesh(spec["scene"]), mesh)
    return run_fem_spec(spec, mesh, work, ranks)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--increments", type=int, default=350, help="increments of schedule I per case (default: all 350)")
    parser.add_argument("--out", default=str(REPO / "results" / "benchmarks"), help="where the CSV table goes")
    args = parser.parse_args()
    config = load_config(REPO / "config" / "config.yaml")
    cases = [("snt1", "direct", 1), ("snt1", "mumps", 1), ("snt1", "iterative", 1), ("snt1", "iterative", 2),
             ("snt2", "iterative", 1), ("snt2", "iterative", 2), ("snt3", "iterative", 1), ("snt3", "iterative", 2)]
    rows, histories = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene, preset, ranks in cases:
            print(f"running {scene} {preset} n={ranks} ...", flush=True)
            history = run_case(config, scene, preset, ranks, args.increments, Path(tmp))
            histories[(scene, preset, ranks)] = history
            nx, ny = config["scenes"][scene]["elements"]
            rows.append({"scene": scene, "elements": f"{nx}x{ny}", "displacement_dofs": 2 * (nx + 1) * (ny + 1),
                         "solver": preset, "ranks": ranks, **{k: history[k].iloc[1:].mean() for k in STEPS}})
    table = pd.DataFrame(rows)
    reference = histories[("snt1", "direct", 1)].reaction_force.to_numpy()
    peak = np.abs(reference).max()
    for i, (scene, preset, ranks) in enumerate(cases):
        if scene == "snt1":
            force = histories[(scene, preset, ranks)].reaction_force.to_numpy()
            table.loc[i, "force_max_error_vs_direct"] = np.abs(force - reference).max() / peak
            table.loc[i, "force_l2_error_vs_direct"] = np.linalg.norm(force - reference) / np.linalg.norm(reference)
    base = table[(table.scene == "snt1") & (table.solver == "direct")].t_increment_s.iloc[0]
    table["speedup_vs_snt1_direct"] = base / table.t_increment_s
    Path(args.out).mkdir(parents=True, exist_ok=True)
    table.to_csv(Path(args.out) / "fem_speed.csv", index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        print(f"\nFEM seconds per increment (mean over increments 2..{args.increments} of schedule I):")
        print(table.to_string(index=False))
    print(f"\nwritten {Path(args.out) / 'fem_speed.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
