"""A workaround for Snakemake's scheduler waking itself ever more often (applied by the Snakefile).

The defect, as a bug report would state it
-------------------------------------------
Affected: Snakemake 9.27.1 (``snakemake/scheduling/job_scheduler.py``), default
``--max-jobs-per-timespan 100/1s``, local execution.

What happens: every pass of ``JobScheduler.schedule`` that has ready jobs ends by calling
``_schedule_reevalutation(timespan)``, which starts a ``threading.Timer`` that releases
``_open_jobs`` one second later and so runs another pass, which starts another timer. Any job
event (a job finished) also releases ``_open_jobs`` and starts one more such chain. Nothing ends a
chain while jobs are ready and waiting for cores, so the number of chains grows with the jobs
finished, and the scheduler's wake-ups per second with it: their total grows with the square of
the time jobs wait. In a paper-scale DAG of this project (299 jobs, 2 cores, two hours) the
Snakemake process created 808,473 timer threads (~230 alive at a time) and its main thread used
1,176 s of CPU in the first 119 minutes: a sixth of one of the two cores the jobs needed.

Reproduce: ``benchmarks/snakemake_scheduler.py`` (independent jobs that only sleep, all ready at
the start, on 2 cores) prints the Snakemake process's CPU with and without this patch; the
difference grows with the square of the run's length (60, 120, 240 jobs of 2 s: 2.9 / 2.0, 7.8 /
3.1, 23.0 / 6.5 s of CPU without / with it).

Expected: at most one pending wake-up; a job event wakes the scheduler anyway. A longer timespan
is no cure: the scheduler then waits for the timer between jobs.

The workaround: :func:`apply` replaces ``_schedule_reevalutation`` by one that keeps at most one
wake-up pending. It applies only where the method and the scheduling loop are exactly those it was
checked against (:data:`CHECKED`, by version and by a hash of their source); anywhere else it
leaves Snakemake as it is and returns False. ``tests/test_run_files.py`` fails when the pinned
Snakemake's code changes under it, so an upgrade is checked again before it is trusted.
"""

from __future__ import annotations

import hashlib
import inspect
import threading

#: Snakemake versions whose ``JobScheduler._schedule_reevalutation`` and ``JobScheduler.schedule``
#: this patch was checked against: version -> sha256 of the two methods' source, concatenated
CHECKED = {"9.27.1": "165ad39f9c8ec0cfa7dc376d316adcf280ccf65f95fe859bd2a8eef779f49685"}

_original = None


def _reevaluate_once(self, delay) -> None:
    if getattr(self, "_ifenn_wakeup_pending", False):
        return
    self._ifenn_wakeup_pending = True

    def wake() -> None:
        self._ifenn_wakeup_pending = False
        self._open_jobs.release()

    timer = threading.Timer(delay, wake)
    timer.daemon = True
    timer.start()


def upstream_fingerprint() -> tuple[str, str] | None:
    """(Snakemake's version, sha256 of its unpatched wake-up method and scheduling loop), or None
    where the scheduler has no such method."""
    import snakemake

    try:
        from snakemake.scheduling.job_scheduler import JobScheduler
    except ImportError:
        return None
    method = _original or getattr(JobScheduler, "_schedule_reevalutation", None)
    if method is None or method is _reevaluate_once:
        return None
    source = inspect.getsource(method) + inspect.getsource(JobScheduler.schedule)
    return snakemake.__version__, hashlib.sha256(source.encode()).hexdigest()


def apply() -> bool:
    """Patch Snakemake's JobScheduler where its code is the one checked (:data:`CHECKED`); False
    elsewhere, leaving it unchanged."""
    global _original
    try:
        from snakemake.scheduling.job_scheduler import JobScheduler
    except ImportError:
        return False
    if JobScheduler._schedule_reevalutation is _reevaluate_once:
        return True
    fingerprint = upstream_fingerprint()
    if fingerprint is None or CHECKED.get(fingerprint[0]) != fingerprint[1]:
        return False
    _original = JobScheduler._schedule_reevalutation
    JobScheduler._schedule_reevalutation = _reevaluate_once
    return True
