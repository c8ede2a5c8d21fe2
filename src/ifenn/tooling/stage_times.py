"""What a workflow run spent, per stage: the sum of the ``benchmark:`` files Snakemake writes.

Every rule writes ``benchmarks/<stage>/<job>.tsv`` (Snakemake's format: a header line, then
``s`` = the job's wall seconds, the process tree's memory, ``cpu_time`` and more). The stage is
the folder under ``benchmarks/`` (fem, ifenn, figures, tables, stability, ...), so the table says
where the CPU time of `snakemake all` goes and what the two cores can at best bring it down to.

Snakemake measures a job's wall time exactly but its CPU time by sampling the process tree
(snakemake/benchmark.py: every 0.5 s for the first 30 samples, then every 30 s) and keeps the last
sample, so ``cpu_time`` misses the CPU a job spent after its last sample: up to 30 s a job
(measured: a job that burnt 40.0 CPU-s recorded 33.0). ``cpu_unsampled_bound`` bounds what the
summed CPU column misses; on two quiet cores the summed wall minus the summed CPU of the paper
DAG is of that size, so it is no idle time.

A working directory keeps the benchmark files of jobs an older workflow had (a run since
dropped from the config, a reference now computed another way): ``dag_benchmarks`` asks Snakemake
(a dry run of the target with every job forced) which benchmark files the current DAG writes, and
``stage_times(..., keep=...)`` counts only those, so the sum is what `snakemake all` spends today.
"""

from __future__ import annotations

import re
import subprocess
import sys
from graphlib import TopologicalSorter
from pathlib import Path

import pandas as pd


def dag_jobs(workdir: str | Path, snakefile: str | Path, configfiles: list[str] | None = None,
             target: str = "all") -> list[dict]:
    """The jobs of ``target`` from Snakemake's dry run with every job forced (nothing is run or
    touched): :func:`parse_dry_run` of its output; ``configfiles`` as the workflow was run with
    (none: the Snakefile's own config)."""
    # the target before --configfile, which takes every word after it
    command = [sys.executable, "-m", "snakemake", target, "-s", str(snakefile), "--directory", str(workdir), "-n",
               "--forceall", "--cores", "1", *(["--configfile", *map(str, configfiles)] if configfiles else [])]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"snakemake's dry run of {target} failed:\n{(done.stdout + done.stderr)[-2000:]}")
    return parse_dry_run(done.stdout + done.stderr)


def parse_dry_run(text: str) -> list[dict]:
    """One dict per job of a Snakemake dry run's output: ``rule``, ``input`` and ``output`` (lists
    of paths relative to the working directory), ``benchmark`` (its file, or None), ``priority``
    (0 where none is printed) and ``wildcards`` (name -> value)."""
    jobs = []
    for line in text.splitlines():
        if match := re.match(r"(?:local)?rule (\w+):$", line):
            jobs.append({"rule": match.group(1), "input": [], "output": [], "benchmark": None, "priority": 0, "wildcards": {}})
        elif jobs and (match := re.match(r"\s+(input|output|benchmark|priority|wildcards): (.+)$", line)):
            key, value = match.groups()
            if key == "benchmark":
                jobs[-1][key] = value.strip()
            elif key == "priority":
                jobs[-1][key] = int(value)
            elif key == "wildcards":
                jobs[-1][key] = dict(item.split("=", 1) for item in value.strip().split(", "))
            else:
                jobs[-1][key] = [item.strip() for item in value.split(",")]
    return jobs


def dag_benchmarks(workdir: str | Path, snakefile: str | Path, configfiles: list[str] | None = None,
                   target: str = "all") -> set[str]:
    """The benchmark files (relative to ``workdir``) that the jobs of ``target`` write
    (:func:`dag_jobs`)."""
    return {job["benchmark"] for job in dag_jobs(workdir, snakefile, configfiles, target) if job["benchmark"]}


def critical_path(jobs: list[dict], wall_s: dict[str, float]) -> tuple[float, list[str]]:
    """The longest chain of jobs that wait for each other (a job waits for the jobs that write its
    inputs), by their measured wall seconds (``wall_s``: benchmark file -> seconds; a job without
    one counts 0): (seconds, the chain's benchmark files in order). No number of cores runs the
    workflow in less."""
    producer = {path: index for index, job in enumerate(jobs) for path in job["output"]}
    waits_for = {index: {producer[path] for path in job["input"] if path in producer} - {index}
                 for index, job in enumerate(jobs)}
    longest: dict[int, tuple[float, int | None]] = {}   # job -> (its chain's end time, the job before)
    for index in TopologicalSorter(waits_for).static_order():
        start, previous = max(((longest[other][0], other) for other in waits_for[index]), default=(0.0, None))
        longest[index] = (start + wall_s.get(jobs[index]["benchmark"] or "", 0.0), previous)
    if not longest:
        return 0.0, []
    end = max(longest, key=lambda index: longest[index][0])
    chain, index = [], end
    while index is not None:
        if jobs[index]["benchmark"]:
            chain.append(jobs[index]["benchmark"])
        index = longest[index][1]
    return longest[end][0], chain[::-1]


def job_times(workdir: str | Path, keep: set[str] | None = None) -> pd.DataFrame:
    """One row per benchmark file: ``stage, job, wall_s, cpu_s`` (the file's last line), longest
    first. ``keep``: only these files (paths relative to ``workdir``); None: every file."""
    root = Path(workdir) / "benchmarks"
    rows = []
    for path in sorted(root.rglob("*.tsv")):
        if keep is not None and str(path.relative_to(workdir)) not in keep:
            continue
        table = pd.read_csv(path, sep="\t")
        if table.empty:
            continue
        last = table.iloc[-1]
        rows.append({"stage": path.relative_to(root).parts[0], "job": str(path.relative_to(root).with_suffix("")),
                     "wall_s": float(last["s"]), "cpu_s": float(last.get("cpu_time", float("nan")))})
    if not rows:
        raise FileNotFoundError(f"no benchmark files under {root}: run the workflow there first")
    return pd.DataFrame(rows).sort_values("wall_s", ascending=False, kind="stable").reset_index(drop=True)


def cpu_unsampled_bound(wall_s) -> float:
    """At most how many CPU seconds the benchmark files' ``cpu_time`` leaves out, summed over jobs
    of these wall times (seconds): a job's CPU after its last sample, on one core at most the wall
    time since that sample: one short interval while the short samples last, then up to one long
    interval (module doc). The intervals are Snakemake's own (its ScheduledPeriodicTimer takes
    BENCHMARK_INTERVAL short samples, then samples every BENCHMARK_INTERVAL seconds)."""
    from snakemake.benchmark import BENCHMARK_INTERVAL, BENCHMARK_INTERVAL_SHORT

    short_s = BENCHMARK_INTERVAL_SHORT * BENCHMARK_INTERVAL
    wall = pd.Series(wall_s, dtype=float)
    return float(wall.where(wall <= short_s, 0.0).clip(upper=BENCHMARK_INTERVAL_SHORT).sum()
                 + (wall[wall > short_s] - short_s).clip(upper=BENCHMARK_INTERVAL).sum())


def cpu_sampling_line(wall_s) -> str:
    """What the CPU column is and what it leaves out for jobs of these wall times (one line, with
    Snakemake's own sampling intervals)."""
    from snakemake.benchmark import BENCHMARK_INTERVAL, BENCHMARK_INTERVAL_SHORT

    return (f"cpu_s is Snakemake's last sample of each job's CPU time (every {BENCHMARK_INTERVAL_SHORT:g} s for "
            f"{BENCHMARK_INTERVAL_SHORT * BENCHMARK_INTERVAL:g} s, then every {BENCHMARK_INTERVAL:g} s): it leaves out at most "
            f"{cpu_unsampled_bound(wall_s):.0f} s here; wall_s is exact")


#: where the workflow's rule machine_speed writes benchmarks/machine_speed.py's numbers
MACHINE_SPEED = Path("results") / "benchmarks" / "machine_speed.json"


def machine_speed_line(workdir: str | Path) -> str | None:
    """One line naming the machine a DAG ran on (its rule machine_speed's record), against the
    reference machine's numbers; None if the DAG has not measured it."""
    import json

    path = Path(workdir) / MACHINE_SPEED
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    reference = record.get("reference", {})
    return (f"the machine ({MACHINE_SPEED}, measured alone at the DAG's start): MUMPS factor + solve of snt1's matrix "
            f"{record['mumps_factor_solve_s']:.3f} s, one apply of its kept Cholesky factor {record['kept_factor_apply_ms']:.1f} ms; "
            f"the reference machine {reference.get('mumps_factor_solve_s', float('nan')):.2f} s, "
            f"{reference.get('kept_factor_apply_ms', float('nan')):.1f} ms (its paper DAG: 66.5 min): scale the seconds above "
            f"before comparing them with another machine's")


def stage_times(workdir: str | Path, keep: set[str] | None = None) -> pd.DataFrame:
    """One row per stage: ``stage, jobs, wall_s`` (sum of the jobs' wall seconds),
    ``longest_s``, ``longest_job``, ``cpu_s`` (sum of cpu_time, where Snakemake measured it; a
    lower bound, :func:`cpu_unsampled_bound`),
    largest first, and a last row ``total``. ``keep``: count only these benchmark files (paths
    relative to ``workdir``, as ``dag_benchmarks`` gives them); None counts every file."""
    jobs = job_times(workdir, keep)
    longest = jobs.loc[jobs.groupby("stage").wall_s.idxmax(), ["stage", "job", "wall_s"]].set_index("stage")
    table = jobs.groupby("stage").agg(jobs=("job", "size"), wall_s=("wall_s", "sum"), cpu_s=("cpu_s", "sum"))
    table["longest_s"], table["longest_job"] = longest.wall_s, longest.job
    table = table.sort_values("wall_s", ascending=False).reset_index()
    total = {"stage": "total", "jobs": int(table.jobs.sum()), "wall_s": table.wall_s.sum(), "cpu_s": table.cpu_s.sum(),
             "longest_s": jobs.wall_s.max(), "longest_job": jobs.job[jobs.wall_s.idxmax()]}
    return pd.concat([table, pd.DataFrame([total])], ignore_index=True).round({"wall_s": 1, "cpu_s": 1, "longest_s": 1})


def unmatched(workdir: str | Path, keep: set[str]) -> tuple[list[str], list[str]]:
    """(stale, missing): the benchmark files under ``workdir`` that no job of the DAG ``keep``
    writes (left out of the sums), and the DAG's files not written yet (a run not finished: the
    sums count less than `snakemake all` spends); paths relative to ``workdir``, sorted."""
    present = {str(p.relative_to(workdir)) for p in Path(workdir, "benchmarks").rglob("*.tsv")}
    return sorted(present - keep), sorted(keep - present)


def wall_bound(table: pd.DataFrame, cores: int, critical_s: float = 0.0) -> float:
    """A lower bound of the workflow's wall time on ``cores`` cores, seconds: the jobs' summed wall
    time shared perfectly, the longest job, or the longest chain of jobs that wait for each other
    (``critical_s``, :func:`critical_path`), whichever is largest (every job here uses one core)."""
    total = table[table.stage == "total"].iloc[0]
    return max(float(total.wall_s) / cores, float(total.longest_s), float(critical_s))


def report(workdir: str | Path, snakefile: str | Path, configfiles: list[str] | None = None, cores: int = 2,
           every_file: bool = False, top: int = 0) -> str:
    """What ``python -m ifenn stage-times`` prints: the stages' sums (a markdown table), the CPU
    sampling and machine lines, the wall-time bound on ``cores`` with the longest chain of jobs, and
    the ``top`` longest jobs; only the benchmark files of the current DAG unless ``every_file``."""
    def some(paths):
        return ", ".join(paths[:8]) + (", ..." if len(paths) > 8 else "")

    lines: list[str] = []
    keep, dag = None, None
    if not every_file:
        dag = dag_jobs(workdir, snakefile, configfiles)
        keep = {job["benchmark"] for job in dag if job["benchmark"]}
        stale, missing = unmatched(workdir, keep)
        if stale:
            lines.append(f"left out: {len(stale)} benchmark files no job of the current DAG writes ({some(stale)})\n")
        if missing:
            lines.append(f"not run yet: {len(missing)} of the DAG's {len(keep)} jobs have no benchmark file ({some(missing)}); "
                         "the sums below count less than `snakemake all` spends\n")
    table = stage_times(workdir, keep)
    lines.append(table.to_markdown(index=False))
    jobs = job_times(workdir, keep)
    lines.append("\n" + cpu_sampling_line(jobs.wall_s))
    machine = machine_speed_line(workdir)
    lines.append(machine or f"the machine: not measured ({MACHINE_SPEED} is written by the workflow's first job)")
    chain_s, chain = 0.0, []
    if dag is not None:
        wall = {f"benchmarks/{job}.tsv": seconds for job, seconds in zip(jobs.job, jobs.wall_s, strict=True)}
        chain_s, chain = critical_path(dag, wall)
    lines.append(f"\non {cores} cores: at least {wall_bound(table, cores, chain_s) / 60:.1f} min "
                 "(summed wall / cores, the longest job, or the longest chain of jobs that wait for each other)")
    if chain:
        steps = [f"{path.removeprefix('benchmarks/').removesuffix('.tsv')} {wall.get(path, 0.0):.0f} s"
                 for path in chain if wall.get(path, 0.0) >= 1.0]
        lines.append(f"the longest chain: {chain_s / 60:.1f} min: " + " -> ".join(steps))
    if top:
        lines.append(f"\nthe {min(top, len(jobs))} longest jobs:\n" + jobs.head(top)[["job", "wall_s", "cpu_s"]].round(1).to_markdown(index=False))
    return "\n".join(lines)
