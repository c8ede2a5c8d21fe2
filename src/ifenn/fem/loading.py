"""Load control: the prescribed displacement of each increment, fixed or adaptive.

A load controller (:class:`LoadControl`) gives the staggered loop the next load, judges each
attempted increment (an adaptive one may refuse it and offer a smaller step) and keeps what a
checkpoint must restore.
"""

from __future__ import annotations

import logging
from typing import Protocol

import numpy as np

log = logging.getLogger(__name__)


class LoadControl(Protocol):
    adaptive: bool
    u_end: float
    increments: int | None  # known in advance (fixed schedules), else None

    def next_load(self, increment: int, u_previous: float) -> float | None:
        """The prescribed displacement of ``increment`` (1-based), None after the last."""

    def begin_increment(self) -> None:
        """A new increment starts (its attempts are counted from here)."""

    def judge(self, phi_change: float, converged: bool) -> bool:
        """Accept the attempted increment (True), or refuse it: next_load then gives the retry's load."""

    def refuses_early(self, phi_change: float) -> bool:
        """Whether an attempt whose phi has moved by ``phi_change`` so far is refused already (its
        remaining staggered passes can be skipped)."""

    def is_last(self, increment: int, u: float) -> bool: ...

    def state(self) -> dict:
        """What a checkpoint keeps (numbers only)."""

    def restore(self, state: dict, rows: list[dict]) -> None:
        """From a checkpoint's ``state``, or from the ``rows`` of a run being continued."""


class FixedLoads:
    """A fixed schedule: the prescribed displacement of increment k is ``loads[k - 1]``."""

    adaptive = False

    def __init__(self, loads: list[float]):
        self.loads = loads
        self.u_end = loads[-1]
        self.increments = len(loads)

    def next_load(self, increment: int, u_previous: float) -> float | None:
        return self.loads[increment - 1] if increment <= len(self.loads) else None

    def begin_increment(self) -> None:
        pass

    def judge(self, phi_change: float, converged: bool) -> bool:
        return True

    def refuses_early(self, phi_change: float) -> bool:
        return False

    def is_last(self, increment: int, u: float) -> bool:
        return increment == len(self.loads)

    def state(self) -> dict:
        return {}

    def restore(self, state: dict, rows: list[dict]) -> None:
        pass


def largest_change(a: np.ndarray, b: np.ndarray, floor: float = 0.0) -> float:
    """max |a - b| over the points where a or b is at least ``floor`` (0 when there are none)."""
    change = np.abs(a - b)
    if floor > 0.0:
        change = change[np.maximum(a, b) >= floor]
    return float(np.max(change, initial=0.0))


class AdaptiveLoads:
    """Adaptive load stepping, a proportional step controller on the largest change of the
    phase field per increment (the crack's advance), counted where phi (before or after) is at
    least ``phi_floor``: the crack and its process zone, not the diffuse damage that AT2 spreads
    everywhere as the load grows (0: everywhere). After each attempt the next step is
    ``step x quiet_fraction x phi_change_max / change``, clamped to ``[cut, grow]`` x step and
    to ``[step_min, step_max]``: the step settles where phi moves by ``quiet_fraction x
    phi_change_max`` per increment, shrinks before the crack runs and grows once phi is quiet.
    An attempt whose phi moved by more than ``phi_change_max`` (or whose staggered iterations
    did not converge) is undone and redone with that smaller step, unless it was made at
    ``step_min`` (always accepted); after ``hold_max`` increments in a row at step_min (phi
    creeping without end, e.g. an IFENN crack that never cuts through) the step grows by
    ``grow`` until phi is quiet again. Ends at ``u_end``. With ``refuse_early``, an attempt with
    staggering to convergence stops as soon as its phi has moved by more than ``phi_change_max``
    (above step_min): it is refused whatever its further passes do (while the crack runs they only
    move phi further), so its remaining passes would be thrown away. Measured on snt1-A-conv on
    the adaptive mesh: 267 of 904 displacement solves were passes of refused 50-pass attempts."""

    adaptive = True
    increments = None

    def __init__(self, settings: dict):
        self.u_end = float(settings["u_end"])
        self.du_min, self.du_max = float(settings["step_min"]), float(settings["step_max"])
        self.grow, self.cut = float(settings["grow"]), float(settings["cut"])
        self.phi_change_max, self.quiet = float(settings["phi_change_max"]), float(settings["quiet_fraction"])
        self.du = float(settings["step_initial"])  # the load step of the next attempt, mm
        self.hold_max = int(settings.get("hold_max", 500))
        self.phi_floor = float(settings.get("phi_floor", 0.0))
        self.refuse_early = bool(settings.get("refuse_early", False))
        self.rejected = 0  # rejected attempts since the last accepted increment
        self.held = 0      # consecutive increments accepted at step_min
        self.released = False

    def next_load(self, increment: int, u_previous: float) -> float | None:
        if u_previous >= self.u_end * (1 - 1e-12):
            return None
        return round(min(u_previous + self.du, self.u_end), 15)

    def begin_increment(self) -> None:
        self.rejected = 0

    def _proportional(self, phi_change: float, converged: bool) -> float:
        """The step factor that would have moved phi by quiet_fraction x phi_change_max."""
        if not converged:
            return self.cut
        target = self.quiet * self.phi_change_max
        return self.grow if phi_change * self.grow <= target else max(target / phi_change, self.cut)

    def refuses_early(self, phi_change: float) -> bool:
        return (self.refuse_early and not self.released and phi_change > self.phi_change_max
                and self.du > self.du_min * (1 + 1e-9))

    def judge(self, phi_change: float, converged: bool) -> bool:
        """Accept the attempted increment (True) or not; sets the next step either way."""
        at_min = self.du <= self.du_min * (1 + 1e-9)
        factor = self._proportional(phi_change, converged)
        if self.released:  # after hold_max increments at step_min: grow until phi is quiet again
            self.released = factor < self.grow
            self.du = min(self.du * self.grow, self.du_max)
            return True
        if (phi_change > self.phi_change_max or not converged) and not at_min:
            self.du = max(self.du * factor, self.du_min)
            self.rejected += 1
            return False
        self.held = self.held + 1 if at_min else 0
        if self.held >= self.hold_max:
            log.warning("phi kept changing for %d increments at the smallest step: growing the step again", self.held)
            self.released, self.held = True, 0
            factor = self.grow
        self.du = min(max(self.du * factor, self.du_min), self.du_max)
        return True

    def is_last(self, increment: int, u: float) -> bool:
        return u >= self.u_end * (1 - 1e-12)

    def state(self) -> dict:
        return {"load_step": self.du}

    def restore(self, state: dict, rows: list[dict]) -> None:
        if "load_step" in state:
            self.du = float(state["load_step"])
        elif len(rows) >= 2:  # continuing another run (IFENN from the FEM switch-over)
            self.du = min(max(rows[-1]["u"] - rows[-2]["u"], self.du_min), self.du_max)


def load_progress_bar(loads, name: str, first: int, u_previous: float):
    """The progress bar of a run driven by ``loads``: in increments for a fixed schedule (its steps
    may differ a thousandfold between segments), in micrometres of prescribed displacement for
    adaptive steps (miniters ~ 0: refreshed on time only). Advance it with :func:`load_progress`."""
    from ifenn.io import progress_bar

    if loads.increments:
        return progress_bar(total=loads.increments, initial=first - 1, desc=name, unit="inc", dynamic_ncols=True)
    return progress_bar(total=round(loads.u_end * 1e3, 3), initial=round(u_previous * 1e3, 3), desc=name, unit="um",
                        miniters=1e-12, dynamic_ncols=True, bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} um [{elapsed}<{remaining}{postfix}]")


def load_progress(loads, u: float, u_previous: float) -> float:
    """How far an increment from ``u_previous`` to ``u`` moves :func:`load_progress_bar`'s bar."""
    return 1 if loads.increments else round((u - u_previous) * 1e3, 6)


def load_control(spec: dict):
    return AdaptiveLoads(spec["adaptive"]) if spec.get("adaptive") else FixedLoads(spec["load"])
