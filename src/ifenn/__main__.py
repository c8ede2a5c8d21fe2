"""Command line (run under ``mpirun -n N`` for N ranks):

  python -m ifenn fem   --spec SPEC.json --mesh MESH.xdmf --out DIR
  python -m ifenn ifenn --spec SPEC.json --mesh MESH.xdmf [--fem-dir FEM_RUN_DIR] [--model MODEL.pt] [--device D] --out DIR
  python -m ifenn adaptive --spec SPEC.json [--model MODEL.pt] [--device D] --out DIR [--start-dir DIR]   (a mesh that follows the crack; one process)
  python -m ifenn pair  --fem-spec SPEC.json --ifenn-spec SPEC.json --mesh MESH.xdmf --model MODEL.pt [--device D]
                        --fem-out DIR --ifenn-out DIR --table CSV --increments-table CSV
                        (a FEM run and its whole-path IFENN run interleaved in one process: both run directories
                        and the whole-run benchmark's rows)
  python -m ifenn cell  --spec SPEC.json --out DIR [--fem-dir FEM_CELL_DIR --model MODEL.pt] [--device D]   (stability sweep)

--device (auto, cpu, cuda; default auto: CUDA when torch sees one): where the network runs.
  python -m ifenn stage-times [WORKDIR] [--cores N]   what a workflow run spent per stage (its benchmark files)
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from ifenn.device import DEVICES


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ifenn", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    fem = sub.add_parser("fem", help="run one FEM phase-field analysis")
    fem.add_argument("--spec", required=True, help="resolved run spec (JSON, from config.fem_run_spec)")
    fem.add_argument("--mesh", required=True, help="mesh XDMF written by the mesh rule")
    fem.add_argument("--out", required=True, help="output directory")
    fem.add_argument("--start-dir", default=None,
                     help="output directory of the FEM run whose saved state this one starts from (a spec with start_from)")
    fem.add_argument("--no-progress", action="store_true")
    hybrid = sub.add_parser("ifenn", help="continue a FEM run from its switch-over increment with IFENN")
    hybrid.add_argument("--spec", required=True, help="resolved IFENN run spec (JSON, from config.ifenn_run_spec)")
    hybrid.add_argument("--mesh", required=True)
    hybrid.add_argument("--fem-dir", default=None, help="output directory of the FEM run it continues (not read with switch_over 'start')")
    hybrid.add_argument("--model", default=None, help="trained PICNN (needed when the predictor is 'picnn')")
    hybrid.add_argument("--out", required=True)
    hybrid.add_argument("--no-progress", action="store_true")
    adaptive = sub.add_parser("adaptive", help="run a FEM run's scene and schedule on a displacement mesh that follows the crack")
    adaptive.add_argument("--spec", required=True, help="resolved run spec (JSON, from config.adaptive_run_spec)")
    adaptive.add_argument("--model", default=None, help="trained PICNN (a verified IFENN run)")
    adaptive.add_argument("--out", required=True)
    adaptive.add_argument("--start-dir", default=None,
                          help="output directory of the adaptive run whose saved state this one starts from (a spec with start_from)")
    adaptive.add_argument("--no-progress", action="store_true")
    cell = sub.add_parser("cell", help="one stability-sweep cell: FEM, or IFENN continuing --fem-dir; failures are recorded")
    cell.add_argument("--spec", required=True)
    cell.add_argument("--out", required=True)
    cell.add_argument("--fem-dir", default=None)
    cell.add_argument("--model", default=None)
    pair = sub.add_parser("pair", help="a FEM run and its whole-path IFENN run interleaved in one process (whole-run benchmark)")
    pair.add_argument("--fem-spec", required=True)
    pair.add_argument("--ifenn-spec", required=True, help="a whole-path run (switch_over 'start') of the FEM run's scene")
    pair.add_argument("--mesh", required=True)
    pair.add_argument("--model", required=True)
    pair.add_argument("--fem-out", required=True)
    pair.add_argument("--ifenn-out", required=True)
    pair.add_argument("--table", required=True, help="the benchmark's summary rows (CSV)")
    pair.add_argument("--increments-table", required=True, help="the benchmark's per-increment rows (CSV)")
    pair.add_argument("--increments", type=int, default=None, help="the tables count the first N increments (default: all)")
    pair.add_argument("--no-progress", action="store_true")
    for command in (hybrid, adaptive, cell, pair):
        command.add_argument("--device", default="auto", choices=DEVICES, help="where the network runs (config 'device'; default auto)")
    times = sub.add_parser("stage-times", help="sum the workflow's benchmark files (benchmarks/<stage>/*.tsv) by stage")
    times.add_argument("workdir", nargs="?", default=".", help="the workflow's working directory (default: here)")
    times.add_argument("--cores", type=int, default=2, help="cores of the wall-time bound printed below the table (default 2)")
    times.add_argument("--snakefile", default=str(Path(__file__).resolve().parents[2] / "Snakefile"),
                       help="count only the benchmark files of this workflow's current DAG (default: the repository's)")
    times.add_argument("--configfile", nargs="+", default=None, help="the config files the workflow ran with (default: the Snakefile's)")
    times.add_argument("--every-file", action="store_true", help="count every benchmark file, stale ones included")
    times.add_argument("--top", type=int, default=0, help="also list the N longest jobs")
    args = parser.parse_args(argv)
    if args.command == "stage-times":
        from ifenn.tooling.stage_times import report

        print(report(args.workdir, args.snakefile, args.configfile, args.cores, args.every_file, args.top))
        return 0
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    for noisy in ("ffcx", "UFL", "root", "compilers"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    if args.command == "fem":
        from ifenn.fem.solver import run_fem

        spec = _read_spec(parser, args.spec, "fem")
        if spec.get("start_from") is not None and args.start_dir is None:
            parser.error(f"run {spec['name']} starts from run {spec['start_from']['run']}'s saved state: --start-dir is needed")
        run_fem(spec, args.mesh, args.out, progress=not args.no_progress, start_dir=args.start_dir)
    elif args.command == "ifenn":
        from ifenn.hybrid.runs import run_ifenn

        spec = _read_spec(parser, args.spec, "ifenn")
        if args.fem_dir is None and spec.get("switch_over", "phi_threshold") != "start":
            parser.error(f"run {spec['name']} switches over from a FEM run ({spec.get('switch_over', 'phi_threshold')}): --fem-dir is needed")
        run_ifenn(spec, args.mesh, args.fem_dir, args.model, args.out, progress=not args.no_progress, device=args.device)
    elif args.command == "adaptive":
        from ifenn.adaptive.run import run_adaptive

        spec = _read_spec(parser, args.spec, "adaptive")
        if spec.get("start_from") is not None and args.start_dir is None:
            parser.error(f"run {spec['name']} starts from run {spec['start_from']['run']}'s saved state: --start-dir is needed")
        run_adaptive(spec, args.out, progress=not args.no_progress, model_path=args.model, device=args.device, start_dir=args.start_dir)
    elif args.command == "pair":
        from ifenn.io import write_csv
        from ifenn.studies.drivers.whole_run_benchmark import paired_whole_run

        specs = [_read_spec(parser, args.fem_spec, "fem"), _read_spec(parser, args.ifenn_spec, "ifenn")]
        summary, increments = paired_whole_run(*specs, args.mesh, args.model, args.fem_out, args.ifenn_out, device=args.device,
                                               increments=args.increments, progress=not args.no_progress)
        write_csv(args.table, summary)
        write_csv(args.increments_table, increments)
    elif args.command == "cell":
        from ifenn.studies.drivers.stability import run_cell

        spec = _read_spec(parser, args.spec, None)
        status = run_cell(spec, args.out, args.fem_dir, args.model, args.device)
        logging.getLogger("ifenn").info("cell %s: %s", spec["name"], status)
    return 0


def _read_spec(parser, path: str, kind: str | None) -> dict:
    """spec.json of a ``kind`` job, checked against its type (:mod:`ifenn.specs`) before anything runs;
    ``kind`` None: a stability cell's, IFENN when it names a predictor, else FEM."""
    from ifenn.specs import typed_spec

    with open(path) as stream:
        spec = json.load(stream)
    try:
        typed_spec(kind or ("ifenn" if "predictor" in spec else "fem"), spec)
    except ValueError as error:
        parser.error(f"{path}: {error}")
    return spec


if __name__ == "__main__":
    sys.exit(main())
