"""Why the three-point beam's force differs from the published curve: the beam of the config
(FEM at h, its schedule) rerun with one modelling choice changed at a time, against the curve
of data/ (config specimens.three-point-bending.measured).

Cases (each a full run of the workflow's solver, `python -m ifenn fem`, one after another):
- configured: the scene as config/config.yaml has it (the load spread over the top's middle
  0.48 mm, rollers under the last 0.08 mm at each end, as the digitiser's own run of this beam
  spreads them);
- point load: the load on the top centre node and the supports on the bottom corner nodes; a
  point force's displacement grows without bound as the mesh is refined (its elastic field is
  logarithmic), a spread one's does not;
- lc x 1/2, lc x 2: the phase field's length on the same mesh (lc/h 3 and 12).

Printed per case: the initial stiffness (force over displacement of the first increment: the
elastic part, set by the supports and the load alone), the peak force, u at the peak and the work
of the load, each as a ratio to the published curve's, and the wall time.

    .venv/bin/python benchmarks/beam_sensitivity.py [--config ...] [--cases ...] [--out DIR]
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import pandas as pd
from _cli import run_fem_spec

from ifenn.config import REPO, fem_run_spec, load_config, validate_config
from ifenn.fem.mesh import build_mesh, write_mesh
from ifenn.studies.tables.metrics import peak
from ifenn.studies.tables.specimens import specimen_table

RUN = "three-point-bending"


def _point_load(scene: dict) -> None:
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    scene["boundary"] = {"points": [{"at": [x0, y0], "y": "fixed"}, {"at": [x1, y0], "y": "fixed"},
                                    {"at": [0.5 * (x0 + x1), y1], "x": "fixed", "y": "-load"}]}


def _lc(factor: float):
    def change(scene: dict) -> None:
        scene["material"] = {**scene["material"], "lc": factor * scene["material"]["lc"]}
    return change


CASES = {"configured": lambda scene: None, "point load": _point_load, "lc x 1/2": _lc(0.5), "lc x 2": _lc(2.0)}


def run_case(config: dict, case: str, work: Path, increments: int | None) -> tuple[pd.DataFrame, float]:
    config = copy.deepcopy(config)
    fine = config["fem_runs"][config["reference_convergence"][RUN]["fine_fem_run"]]["scene"]
    for scene in {config["fem_runs"][RUN]["scene"], fine}:   # the finer reference must stay the same specimen
        CASES[case](config["scenes"][scene])
    config = validate_config(config, petsc_names=False)   # the changed scene passes the config's checks
    spec = fem_run_spec(config, RUN)
    name = case.replace(" ", "_").replace("/", "")
    spec.update(name=name, save_fields=[], checkpoint_every=10**6, load=spec["load"][:increments])
    work.mkdir(parents=True, exist_ok=True)
    write_mesh(build_mesh(spec["scene"]), work / f"{name}.xdmf")
    start = time.perf_counter()
    history = run_fem_spec(spec, work / f"{name}.xdmf", work)
    return history, time.perf_counter() - start


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cli.add_argument("--config", nargs="+", default=[str(REPO / "config" / "config.yaml")])
    cli.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    cli.add_argument("--increments", type=int, default=None, help="the schedule's first N increments (default: all)")
    cli.add_argument("--out", default="results/benchmarks/beam_sensitivity")
    args = cli.parse_args()
    config = load_config(*args.config)
    measured = pd.read_csv(REPO / config["specimens"][RUN]["measured"]["file"], comment="#")
    out = Path(args.out)
    rows = []
    for case in args.cases:
        history, wall = run_case(config, case, out, args.increments)
        table = specimen_table({case: history}, measured).set_index("run")
        first = history.iloc[0]
        m_stiff = measured.load_N.iloc[1] / measured.displacement_mm.iloc[1]
        force, u_peak = peak(history.u.to_numpy(), history.reaction_force.to_numpy())
        rows.append({"case": case, "stiffness_N_per_mm": first.reaction_force / first.u, "stiffness_ratio": first.reaction_force / first.u / m_stiff,
                     "peak_N": force, "peak_ratio": table.loc[case, "peak_ratio"], "u_peak_mm": u_peak,
                     "u_peak_ratio": table.loc[case, "u_peak_ratio"], "work_ratio": table.loc[case, "work_ratio"],
                     "peak_at_last_increment": bool(u_peak >= history.u.iloc[-1]), "wall_s": wall})
        print(pd.DataFrame(rows).to_string(index=False, float_format="%.4g"), flush=True)
    frame = pd.DataFrame(rows)
    frame.to_csv(out / "beam_sensitivity.csv", index=False, float_format="%.6g")
    print(f"published: peak {measured.load_N.max():.4g} N at {measured.displacement_mm[measured.load_N.idxmax()]:.4g} mm, "
          f"initial stiffness {m_stiff:.4g} N/mm; written {out / 'beam_sensitivity.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
