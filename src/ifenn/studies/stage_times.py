"""What a workflow run spent, per stage: the sum of the ``benchmark:`` files Snakemake writes.

Every rule writes ``benchmarks/<stage>/<job>.tsv`` (Snakemake's format: a header line, then
``s`` = the job's wall seconds, the process tree's memory, ``cpu_time`` and more). The stage is
the folder under ``benchmarks/`` (fem, ifenn, figures, tables, stability, ...), so the table says
where the CPU time of `snakemake all` goes and what the two cores can at best bring it down to.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def stage_times(workdir: str | Path) -> pd.DataFrame:
    """One row per stage: ``stage, jobs, wall_s`` (sum of the jobs' wall seconds),
    ``longest_s``, ``longest_job``, ``cpu_s`` (sum of cpu_time, where Snakemake measured it),
    largest first, and a last row ``total``."""
    root = Path(workdir) / "benchmarks"
    rows = []
    for path in sorted(root.rglob("*.tsv")):
        table = pd.read_csv(path, sep="\t")
        if table.empty:
            continue
        last = table.iloc[-1]
        rows.append({"stage": path.relative_to(root).parts[0], "job": str(path.relative_to(root).with_suffix("")),
                     "wall_s": float(last["s"]), "cpu_s": float(last.get("cpu_time", float("nan")))})
    if not rows:
        raise FileNotFoundError(f"no benchmark files under {root}: run the workflow there first")
    jobs = pd.DataFrame(rows)
    longest = jobs.loc[jobs.groupby("stage").wall_s.idxmax(), ["stage", "job", "wall_s"]].set_index("stage")
    table = jobs.groupby("stage").agg(jobs=("job", "size"), wall_s=("wall_s", "sum"), cpu_s=("cpu_s", "sum"))
    table["longest_s"], table["longest_job"] = longest.wall_s, longest.job
    table = table.sort_values("wall_s", ascending=False).reset_index()
    total = {"stage": "total", "jobs": int(table.jobs.sum()), "wall_s": table.wall_s.sum(), "cpu_s": table.cpu_s.sum(),
             "longest_s": jobs.wall_s.max(), "longest_job": jobs.job[jobs.wall_s.idxmax()]}
    return pd.concat([table, pd.DataFrame([total])], ignore_index=True).round({"wall_s": 1, "cpu_s": 1, "longest_s": 1})


def wall_bound(table: pd.DataFrame, cores: int) -> float:
    """A lower bound of the workflow's wall time on ``cores`` cores, seconds: the jobs' summed wall
    time shared perfectly, or the longest job, whichever is larger (every job here uses one core;
    dependencies can only lengthen it)."""
    total = table[table.stage == "total"].iloc[0]
    return max(float(total.wall_s) / cores, float(total.longest_s))
