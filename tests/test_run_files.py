"""The files of a run: a damaged model, mesh, fields.h5 or checkpoint ends in one line that
names the file and how to get it back; one process at a time writes a run directory."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from ifenn import run_files
from ifenn.io import CorruptFileError
from ifenn.run_files import RunInProgressError, exclusive_writer

ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1"}


def _truncate(path, keep=0.5):
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _overwrite_middle(path, size=4096):
    data = bytearray(path.read_bytes())
    start = len(data) // 3
    data[start:start + size] = os.urandom(min(size, len(data) - start))
    path.write_bytes(bytes(data))


def _assert_one_line_naming(info, path, rebuild):
    message = str(info.value)
    assert "\n" not in message and str(path) in message and rebuild in message, message
    assert info.value.__cause__ is None and info.value.__suppress_context__, "the library's traceback is dropped"


def test_truncated_model_names_the_file(tmp_path):
    from ifenn.network.picnn import PICNN, load_picnn, save_picnn

    path = tmp_path / "model.pt"
    save_picnn(PICNN(), path, h_px=0.0025, Gc=2.7, lc=0.015, config_hash="x")
    load_picnn(path)  # intact: reads
    _truncate(path)
    with pytest.raises(CorruptFileError) as info:
        load_picnn(path)
    _assert_one_line_naming(info, path, "rerun the workflow")


def test_mesh_overwritten_in_part_names_the_file(quick_config, tmp_path):
    from ifenn.fem.mesh import build_mesh, read_dolfinx_mesh, write_mesh

    path = tmp_path / "snt-small.xdmf"
    write_mesh(build_mesh(quick_config["scenes"]["snt-small"]), path)
    assert read_dolfinx_mesh(path).topology.index_map(2).size_local == 16 * 16
    _overwrite_middle(path.with_suffix(".h5"))
    with pytest.raises(CorruptFileError) as info:
        read_dolfinx_mesh(path)
    _assert_one_line_naming(info, path, "rerun the workflow")
    with pytest.raises(FileNotFoundError, match="no mesh file"):
        read_dolfinx_mesh(tmp_path / "missing.xdmf")


def test_truncated_fields_names_the_file(tmp_path):
    path = tmp_path / "fields.h5"
    state = {"increment": 3, "u": 1e-3, "history": np.ones((40, 40)), "phase_field_gp": np.zeros((40, 40)),
             "phase_field": np.zeros(81), "displacement": np.zeros((81, 2))}
    run_files.write_fields(path, {"run": "x"}, [state])
    assert run_files.saved_increments(path) == [3]
    _truncate(path, keep=0.3)
    for read in (run_files.saved_increments, run_files.fields_attrs, run_files.read_states):
        with pytest.raises(CorruptFileError) as info:
            read(path)
        _assert_one_line_naming(info, path, "rerun the workflow")


def test_damaged_checkpoint_names_the_file(tmp_path):
    path = tmp_path / "checkpoint.npz"
    run_files.write_state(path, {"increment": 7, "rows": np.random.default_rng(0).random((200, 20))})
    assert int(run_files.read_state(path)["increment"]) == 7
    _truncate(path, keep=0.6)
    with pytest.raises(CorruptFileError) as info:
        run_files.read_state(path)
    _assert_one_line_naming(info, path, "starts again from its first increment")


HOLD = """
import sys, time
from ifenn.run_files import exclusive_writer
with exclusive_writer(sys.argv[1]):
    print("holding", flush=True)
    time.sleep(600)
"""


def test_a_second_writer_refuses_at_once_naming_the_holder(quick_spec, tmp_path):
    """A run in progress (here a process that holds the lock, as an orphaned run would) makes
    a second run on the same directory refuse before it reads or writes anything; once the
    holder dies (kill -9: no clean-up of its own), the directory is free again."""
    from ifenn.fem.solver import run_fem

    run_dir = tmp_path / "run"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(run_dir)], env=ENV, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "holding"
        (run_dir / ".work" / "checkpoint.npz").write_bytes(b"the holder's")
        with pytest.raises(RunInProgressError, match=rf"is being written by pid {holder.pid} on .*wait for it to finish"):
            # the mesh does not exist: the refusal comes before anything is read
            run_fem(quick_spec("snt1-I"), tmp_path / "no-mesh.xdmf", run_dir, progress=False)
        assert (run_dir / ".work" / "checkpoint.npz").read_bytes() == b"the holder's"  # untouched
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    with exclusive_writer(run_dir):  # the system released the killed holder's lock
        pass


def test_stage_times_sum_the_benchmark_files_and_bound_the_wall(tmp_path):
    """stage-times: per stage the jobs, their summed and longest wall time; the bound on N cores is
    the summed wall over N or the longest job, whichever is larger."""
    from ifenn.tooling.stage_times import job_times, stage_times, wall_bound

    for stage, job, seconds in (("fem", "a", 100.0), ("fem", "b", 300.0), ("ifenn", "c", 50.0)):
        (tmp_path / "benchmarks" / stage).mkdir(parents=True, exist_ok=True)
        (tmp_path / "benchmarks" / stage / f"{job}.tsv").write_text(f"s\tcpu_time\n{seconds}\t{seconds / 2}\n")
    table = stage_times(tmp_path).set_index("stage")
    assert table.loc["fem", "jobs"] == 2 and table.loc["fem", "wall_s"] == 400.0 and table.loc["fem", "longest_job"] == "fem/b"
    assert table.loc["total", "wall_s"] == 450.0 and table.loc["total", "cpu_s"] == 225.0
    assert wall_bound(table.reset_index(), 2) == 300.0 and wall_bound(table.reset_index(), 1) == 450.0
    jobs = job_times(tmp_path)
    assert list(jobs.job) == ["fem/b", "fem/a", "ifenn/c"] and list(jobs.wall_s) == [300.0, 100.0, 50.0]


def test_the_cpu_column_misses_at_most_the_time_since_the_last_sample():
    """Snakemake samples a job's CPU every 0.5 s for 15 s, then every 30 s, and keeps the last
    sample: a 10-s job misses at most 0.5 s, a 20-s job the 5 s since its 15-s sample, a long one
    a whole 30-s interval."""
    from ifenn.tooling.stage_times import cpu_unsampled_bound

    assert cpu_unsampled_bound([0.2]) == 0.2 and cpu_unsampled_bound([10.0]) == 0.5
    assert cpu_unsampled_bound([20.0]) == 5.0 and cpu_unsampled_bound([1000.0]) == 30.0
    assert cpu_unsampled_bound([10.0, 20.0, 1000.0]) == 35.5 and cpu_unsampled_bound([]) == 0.0


def test_stage_times_name_the_machine_the_dag_ran_on(tmp_path):
    """The workflow's first job records the machine's speed (benchmarks/machine_speed.py --out);
    stage-times quotes it beside the reference machine's, and says when a DAG has none."""
    import json

    from ifenn.tooling.stage_times import MACHINE_SPEED, machine_speed_line

    assert machine_speed_line(tmp_path) is None
    (tmp_path / MACHINE_SPEED).parent.mkdir(parents=True)
    (tmp_path / MACHINE_SPEED).write_text(json.dumps({"mumps_factor_solve_s": 0.1985, "kept_factor_apply_ms": 26.31,
                                                      "reference": {"mumps_factor_solve_s": 0.14, "kept_factor_apply_ms": 6.9}}))
    line = machine_speed_line(tmp_path)
    assert "0.199 s" in line and "26.3 ms" in line and "0.14 s" in line and "6.9 ms" in line


def test_the_longest_chain_of_jobs_that_wait_for_each_other():
    """critical_path: a job waits for the jobs that write its inputs; the chain with the largest
    summed wall time bounds the workflow on any number of cores, and the bound says so."""
    from ifenn.tooling.stage_times import critical_path, parse_dry_run, wall_bound

    dry = """
rule mesh:
    output: results/mesh.xdmf
    jobid: 3
    benchmark: benchmarks/mesh/m.tsv
rule fem:
    input: results/spec_a.json, results/mesh.xdmf
    output: results/fem/a/history.csv, results/fem/a/fields.h5
    benchmark: benchmarks/fem/a.tsv
rule fem:
    input: results/spec_b.json, results/mesh.xdmf, results/fem/a/fields.h5
    output: results/fem/b/history.csv
    benchmark: benchmarks/fem/b.tsv
rule ifenn:
    input: results/mesh.xdmf, results/fem/a/fields.h5
    output: results/ifenn/c/history.csv
    benchmark: benchmarks/ifenn/c.tsv
localrule all:
    input: results/fem/b/history.csv, results/ifenn/c/history.csv
    jobid: 0
"""
    jobs = parse_dry_run(dry)
    assert [job["rule"] for job in jobs] == ["mesh", "fem", "fem", "ifenn", "all"]
    assert jobs[2]["input"][2] == "results/fem/a/fields.h5" and jobs[4]["benchmark"] is None
    wall = {"benchmarks/mesh/m.tsv": 1.0, "benchmarks/fem/a.tsv": 100.0, "benchmarks/fem/b.tsv": 50.0, "benchmarks/ifenn/c.tsv": 120.0}
    assert critical_path(jobs, wall) == (221.0, ["benchmarks/mesh/m.tsv", "benchmarks/fem/a.tsv", "benchmarks/ifenn/c.tsv"])
    wall["benchmarks/fem/b.tsv"] = 130.0
    assert critical_path(jobs, wall)[0] == 231.0
    assert critical_path([], wall) == (0.0, [])
    import pandas as pd
    table = pd.DataFrame([{"stage": "total", "wall_s": 401.0, "longest_s": 130.0}])
    assert wall_bound(table, 2) == 200.5 and wall_bound(table, 2, critical_s=231.0) == 231.0


def test_stage_times_name_the_stale_and_the_missing_files(tmp_path):
    """Against the DAG's own list: files no job writes are stale (left out of the sums, by
    ``keep``), the DAG's files not written yet are missing (a run not finished)."""
    from ifenn.tooling.stage_times import stage_times, unmatched

    for job, seconds in (("fem/a", 100.0), ("fem/old", 900.0)):
        (tmp_path / "benchmarks" / job).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "benchmarks" / f"{job}.tsv").write_text(f"s\tcpu_time\n{seconds}\t{seconds}\n")
    keep = {"benchmarks/fem/a.tsv", "benchmarks/ifenn/b.tsv"}
    assert unmatched(tmp_path, keep) == (["benchmarks/fem/old.tsv"], ["benchmarks/ifenn/b.tsv"])
    assert stage_times(tmp_path, keep).set_index("stage").loc["total", "wall_s"] == 100.0


def test_the_snakemake_patch_is_checked_against_the_pinned_snakemake():
    """ifenn.snakemake_patch applies only to the Snakemake code it was checked against: the pinned
    version's wake-up method and scheduling loop hash to what CHECKED records. An upgrade that
    changes either fails here, so the patch is measured again (benchmarks/snakemake_scheduler.py)
    before it is trusted, or removed."""
    import re

    from ifenn import snakemake_patch

    repo = __import__("pathlib").Path(__file__).resolve().parents[1]
    pinned = re.search(r"^snakemake==(\S+)$", (repo / "requirements.txt").read_text(), flags=re.M).group(1)
    assert pinned in snakemake_patch.CHECKED
    assert snakemake_patch.upstream_fingerprint() == (pinned, snakemake_patch.CHECKED[pinned])
    # elsewhere it leaves Snakemake alone
    saved = dict(snakemake_patch.CHECKED)
    try:
        snakemake_patch.CHECKED.clear()
        snakemake_patch.CHECKED[pinned] = "0" * 64
        from snakemake.scheduling.job_scheduler import JobScheduler

        if JobScheduler._schedule_reevalutation is not snakemake_patch._reevaluate_once:
            assert not snakemake_patch.apply()
    finally:
        snakemake_patch.CHECKED.clear()
        snakemake_patch.CHECKED.update(saved)


def test_the_snakemake_scheduler_keeps_one_wakeup_pending():
    """ifenn.snakemake_patch: the scheduler's re-evaluation timers no longer multiply; asked for
    many wake-ups while one is pending, the scheduler is woken once, and again after that one."""
    import threading
    import time

    from snakemake.scheduling.job_scheduler import JobScheduler

    from ifenn import snakemake_patch

    assert snakemake_patch.apply() and JobScheduler._schedule_reevalutation is snakemake_patch._reevaluate_once

    class Scheduler:
        _open_jobs = threading.Semaphore(0)

    scheduler = Scheduler()
    for _ in range(50):
        JobScheduler._schedule_reevalutation(scheduler, 0.05)
    time.sleep(0.3)
    woken = 0
    while scheduler._open_jobs.acquire(blocking=False):
        woken += 1
    assert woken == 1
    JobScheduler._schedule_reevalutation(scheduler, 0.05)
    assert scheduler._open_jobs.acquire(timeout=2)
