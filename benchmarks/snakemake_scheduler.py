"""What Snakemake's scheduler costs while jobs run, with and without ``ifenn.snakemake_patch``.

The paper DAG's condition in miniature: more jobs ready than cores, for a long time. Every
scheduling pass that finds ready jobs but no free core starts a one-second timer that runs the
scheduler again (``JobScheduler._schedule_reevalutation``), and each job event starts such a
chain, which lives as long as jobs wait: the wake-ups per second grow with the jobs finished, so
their cost grows with the square of the DAG's length. The benchmark runs ``--jobs`` independent
jobs of ``--seconds`` each (they only sleep) on 2 cores in a fresh Snakemake, without the patch
and with it, and prints the CPU seconds of the Snakemake process and the wall time.

    .venv/bin/python benchmarks/snakemake_scheduler.py [--jobs 60] [--seconds 2]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SNAKEFILE = """
if config.get("patch"):
    from ifenn import snakemake_patch
    assert snakemake_patch.apply()

rule all:
    input: expand("done/{i}", i=range(int(config["jobs"])))

rule job:
    output: "done/{i}"
    shell: "sleep {config[seconds]} && touch {output}"
"""


def measure(jobs: int, seconds: float, patch: bool) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        snakefile = Path(folder) / "Snakefile"
        snakefile.write_text(SNAKEFILE)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "snakemake", "-s", str(snakefile), "--cores", "2", "--quiet", "all",
                        "--config", f"jobs={jobs}", f"seconds={seconds}", f"patch={int(patch)}"],
                       cwd=folder, check=True, capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
        wall = time.perf_counter() - started
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"patch": patch, "jobs": jobs, "seconds": seconds, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=60, help="independent jobs, all ready at the start (default 60)")
    parser.add_argument("--seconds", type=float, default=2.0, help="seconds each job sleeps (default 2)")
    args = parser.parse_args()
    import snakemake

    print(f"Snakemake {snakemake.__version__}, {args.jobs} jobs of {args.seconds:g} s on 2 cores")
    for patch in (False, True):
        row = measure(args.jobs, args.seconds, patch)
        print(f"  {'with' if patch else 'without'} the patch: wall {row['wall_s']} s, "
              f"Snakemake's CPU {row['cpu_s']} s ({row['cpu_s'] / row['wall_s']:.0%} of a core)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
