"""The solvers' own failures, apart from every other error.

A stability sweep labels a cell "diverged" only when one of these is raised
(:mod:`ifenn.studies.drivers.stability`); any other error (a CUDA out-of-memory, a bug, a bad file)
stops the job with its message, so a broken machine is never read as a physical result.
"""

from __future__ import annotations


class SolverDivergedError(RuntimeError):
    """A solve failed to converge: a Krylov solve's reason, or the pixel correction's
    iterations exhausted; the message names the increment and the field."""


class NonFiniteResultError(SolverDivergedError, FloatingPointError):
    """An increment produced a non-finite force or phase field."""
