"""A workaround for Snakemake 9's scheduler waking itself ever more often (applied by the Snakefile).

With the default ``--max-jobs-per-timespan 100/1s``, every scheduling pass that finds the cores
busy starts a 1-s ``threading.Timer`` to run the scheduler again
(``JobScheduler._schedule_reevalutation``), and each wake-up starts another: every job event adds
a chain, so the wake-ups per second grow with the jobs finished. In the paper DAG (299 jobs, 2
cores; environment-notes.md, twenty-first session) Snakemake's main thread took 1,176 s of CPU in
119 minutes, 808,473 timers, ~230 alive at a time, a sixth of a core taken from the two jobs.
Keeping at most one wake-up pending leaves the scheduling as it was (120 one-second jobs on 2
cores: 65.6 s against 66.7 s) at a fraction of the scheduler's CPU. A longer timespan is no cure:
the scheduler then waits for the timer (126 s for the same 120 jobs).
"""

from __future__ import annotations

import threading


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


def apply() -> bool:
    """Patch Snakemake's JobScheduler where it has the method (Snakemake 9); False elsewhere."""
    try:
        from snakemake.scheduling.job_scheduler import JobScheduler
    except ImportError:
        return False
    if not hasattr(JobScheduler, "_schedule_reevalutation"):
        return False
    JobScheduler._schedule_reevalutation = _reevaluate_once
    return True
