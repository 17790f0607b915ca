"""Step-size control by contact state, with cut-back on Newton failure.

Three step sizes as in the drill paper: ``open_s`` (no contact closed), ``closed_s`` (some contact
closed) and ``change_s`` (a contact opens or closes). Contact events are located by rejecting a
step whose contact set changed while dt > change_s and retrying with a quarter of it (an *event
refinement*), and approached by shrinking dt towards the predicted closure time. A step whose
Newton iteration fails is retried with half the step (a *cut-back*); after a cut-back the step may
grow again by ``growth`` per accepted step. Below ``min_s`` the run stops with NumericalFailure.

All sizes a run uses are ``open_s / 2^k``, ``closed_s / 2^k`` or ``change_s / 2^k`` (plus a final
partial step), so the few factorisations of K_eff are cached and reused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from app.errors import NumericalFailure


@dataclass(frozen=True)
class StepSizes:
    open_s: float
    closed_s: float
    change_s: float
    min_s: float
    growth: float = 2.0

    def __post_init__(self):
        if not (self.open_s > 0 and self.closed_s > 0 and self.change_s > 0 and self.min_s > 0):
            raise ValueError("step sizes must be positive")
        if self.min_s > self.change_s:
            raise ValueError("min_s must not exceed change_s")


@dataclass(frozen=True)
class ContactStatus:
    """Which contacts are closed, and the earliest predicted closure of an open one [s] (inf if none
    approaches)."""

    closed: tuple[bool, ...]
    time_to_closure_s: float

    @property
    def any_closed(self) -> bool:
        return any(self.closed)


class ContactMonitor:
    """Evaluates :class:`ContactStatus` of a state from the interactions' own status (closed, time
    to closure), in the order of ``system.interactions``."""

    def __init__(self, system):
        self.system = system

    def status(self, state) -> ContactStatus:
        sysm = self.system
        closed, closure = [], math.inf
        for f in sysm.fields:
            f.u_mid.x.array[:] = state.u
            f.v_mid.x.array[:] = state.v
        for c in sysm.interactions:
            is_closed, time_to_closure = c.status(sysm, state)
            closed.append(bool(is_closed))
            closure = min(closure, time_to_closure)
        return ContactStatus(tuple(closed), closure)


class StepController:
    """Chooses the next dt and counts cut-backs and event refinements."""

    def __init__(self, sizes: StepSizes):
        self.sizes = sizes
        self.cutbacks = 0
        self.event_refinements = 0
        self._cap = math.inf

    def snapshot(self) -> dict:
        """JSON-able state (for checkpoints): the growth cap after cut-backs and the counters."""
        return {"cap_s": None if self._cap == math.inf else self._cap, "cutbacks": self.cutbacks,
                "event_refinements": self.event_refinements}

    def restore(self, snap: dict) -> None:
        self._cap = math.inf if snap["cap_s"] is None else float(snap["cap_s"])
        self.cutbacks = int(snap["cutbacks"])
        self.event_refinements = int(snap["event_refinements"])

    def _snap(self, level_s: float, dt: float) -> float:
        """Largest level_s / 2^k not above dt."""
        if dt >= level_s:
            return level_s
        return level_s / 2 ** math.ceil(math.log2(level_s / dt) - 1e-12)

    def propose(self, status: ContactStatus, changed: bool) -> float:
        sz = self.sizes
        if changed:
            dt = sz.change_s
        elif status.any_closed:
            dt = sz.closed_s
        else:
            dt = sz.open_s
            if status.time_to_closure_s < dt:
                dt = max(sz.change_s, self._snap(sz.open_s, 0.5 * status.time_to_closure_s))
        if dt > self._cap:
            dt = self._snap(dt, self._cap)
        return dt

    def accepted(self, dt: float) -> None:
        """Let the step grow again after cut-backs."""
        if self._cap < math.inf:
            self._cap = dt * self.sizes.growth
            if self._cap >= max(self.sizes.open_s, self.sizes.closed_s):
                self._cap = math.inf

    def cut_back(self, dt: float, why: str) -> float:
        """Halve dt after a failed Newton solve; NumericalFailure below the floor."""
        self.cutbacks += 1
        new_dt = 0.5 * dt
        if new_dt < self.sizes.min_s:
            raise NumericalFailure(
                f"transient step failed ({why}) at dt = {dt:.3e} s after {self.cutbacks} cut-backs; "
                f"halving would go below the floor min_s = {self.sizes.min_s:.3e} s")
        self._cap = new_dt
        return new_dt

    def refine_event(self, dt: float) -> float | None:
        """A step changed the contact set: return a smaller dt to retry with, or None to accept."""
        if dt <= self.sizes.change_s * (1 + 1e-9):
            return None
        self.event_refinements += 1
        return max(0.25 * dt, self.sizes.change_s)
