"""The SLURM profile with the real executor, against a one-node cluster on localhost
(workflow/cluster/local-slurm.sh): a slice of the quick DAG (mesh, the training FEM run with
2 MPI ranks, training data, PICNN training, one IFENN run) is submitted job by job through
`--profile profiles/slurm` and must give the same numbers as the same targets run locally.

Needs root and the Debian packages of `make slurm-up`; skipped (with the reason) otherwise.
The test starts the cluster when it is not running and stops it again afterwards.
Deselect it with `-m "not slurm"`; it takes about 4-5 minutes on 2 cores."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
CLUSTER = REPO / "workflow" / "cluster" / "local-slurm.sh"
SNAKEMAKE = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile")]
# The executor guesses the account with `sacct -u $USER`; a minimal environment may lack USER.
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1",
       "USER": os.environ.get("USER") or "root"}
# a guard against a hang, not a speed limit: CI's own limit (90 min); the suite must pass on a
# slow or busy machine
HANG_GUARD_S = 5400
# a site's partition/account must not leak into the local cluster's run
for variable in ("SBATCH_PARTITION", "SBATCH_ACCOUNT"):
    ENV.pop(variable, None)
TARGET = "results/ifenn/snt1-I/history.csv"
# the training FEM run of the quick profile, declared with 2 MPI ranks (-> sbatch --ntasks=2)
OVERLAY = "fem_runs:\n  snt1-I: {mpi_ranks: 2}\n"

pytestmark = pytest.mark.slurm


@pytest.fixture(scope="module")
def local_cluster():
    if os.geteuid() != 0:
        pytest.skip("the local SLURM cluster starts system daemons: needs root")
    missing = [b for b in ("slurmctld", "slurmd", "slurmdbd", "munged", "sbatch", "sacct", "mariadbd")
               if shutil.which(b) is None and not Path("/usr/sbin", b).exists()]
    if missing:
        pytest.skip(f"SLURM packages not installed ({', '.join(missing)} missing): `make slurm-up` installs them")
    was_running = subprocess.run([str(CLUSTER), "status"], capture_output=True, text=True).returncode == 0
    up = subprocess.run([str(CLUSTER), "up"], capture_output=True, text=True, timeout=HANG_GUARD_S)
    if up.returncode != 0:
        pytest.skip(f"the local SLURM cluster did not start: {(up.stdout + up.stderr)[-1500:]}")
    yield
    if not was_running:
        subprocess.run([str(CLUSTER), "down"], capture_output=True, text=True, timeout=HANG_GUARD_S)


def _slice(work, *options):
    """Start Snakemake on the slice in ``work``; returns the process (its output is piped)."""
    (work / "overlay.yaml").write_text(OVERLAY)
    return subprocess.Popen([*SNAKEMAKE, "--directory", str(work), "--configfile", str(REPO / "config" / "quick.yaml"),
                             str(work / "overlay.yaml"), *options, TARGET],
                            cwd=work, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _finish(process):
    log, _ = process.communicate(timeout=HANG_GUARD_S)
    assert process.returncode == 0, log[-6000:]
    return log


def _values(csv):
    """A history.csv or loss.csv without its wall-time columns (t_*_s, wall_s)."""
    table = pd.read_csv(csv)
    return table[[c for c in table.columns if not (c.startswith("t_") or "wall" in c)]]


def test_quick_slice_through_slurm_equals_local_run(local_cluster, tmp_path):
    slurm, local = tmp_path / "slurm", tmp_path / "local"
    slurm.mkdir()
    local.mkdir()
    # The local reference runs beside the cluster run, which mostly waits between status checks
    # (the slice is a chain: one job at a time on each side; --cores 2 as the node has 2 CPUs).
    local_run = _slice(local, "--cores", "2")
    try:
        # the profile as shipped; the first status check after 5 s instead of the plugin's 40
        log = _finish(_slice(slurm, "--profile", str(REPO / "profiles" / "slurm"),
                             "--slurm-init-seconds-before-status-checks", "5"))
        _finish(local_run)
    finally:
        if local_run.poll() is None:
            local_run.kill()
    # "Job 3 has been submitted with SLURM jobid 3 (log: .../slurm_logs/rule_fem/snt1-I/3.log)."
    submitted = {line.split("SLURM jobid ")[1].split()[0]: line.split("/rule_")[1].split("/")[0]
                 for line in log.splitlines() if "has been submitted with SLURM jobid" in line}
    assert sorted(submitted.values()) == ["fem", "ifenn", "mesh", "train_picnn", "training_data"], log[-4000:]

    # what SLURM recorded: every job completed, the FEM job had 2 CPUs (2 tasks of 1 thread)
    jobs = subprocess.run(["sacct", "-X", "-n", "--parsable2", "--format=JobIdRaw,State,AllocCPUS", "-j", ",".join(submitted)],
                          capture_output=True, text=True, env=ENV, check=True).stdout
    recorded = {job: (state, int(cpus)) for job, state, cpus in (line.split("|") for line in jobs.splitlines())}
    assert set(recorded) == set(submitted) and all(state == "COMPLETED" for state, _ in recorded.values()), jobs
    assert {submitted[job]: cpus for job, (_, cpus) in recorded.items()}["fem"] == 2, jobs

    # same code, same ranks and threads: the numbers agree to the FEM's solver tolerance. Under
    # SLURM's launcher the two ranks' sums may reduce in another order, and CG (rtol 1e-8) then
    # stops on other round-offs: measured 2.3e-6 of the largest force, 1.7e-5 of the training loss
    # the same tolerance the direct and iterative solvers agree to (test_solver)
    for csv, tolerance in (("fem/snt1-I/history.csv", 1e-5), ("picnn/loss.csv", 1e-4), ("picnn/scores.csv", 1e-5),
                           ("ifenn/snt1-I/history.csv", 1e-5)):
        there, here = _values(slurm / "results" / csv), _values(local / "results" / csv)
        assert list(there.columns) == list(here.columns) and len(there) == len(here), csv
        for column in here.select_dtypes("number"):
            scale = max(float(here[column].abs().max()), 1e-300)
            assert float((there[column] - here[column]).abs().max()) <= tolerance * scale, (csv, column)
    for provenance in (slurm, local):
        assert '"mpi_ranks": 2' in (provenance / "results/fem/snt1-I/provenance.json").read_text()
