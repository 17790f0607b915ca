"""The time loop: update loads -> solve -> check convergence reason -> export -> shift state -> adapt dt.

Loads and Dirichlet drives are updated inside the step (they are evaluated at the step's own
times), the SNES converged reason is checked on every attempt, and a failed attempt is retried with
a smaller dt instead of ending the run (see :mod:`app.transient.control`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from app.transient.control import ContactMonitor, StepController
from app.transient.coupled import CoupledSystem
from app.transient.state import TransientState


@dataclass
class RunStatistics:
    steps: int = 0
    attempts: int = 0
    cutbacks: int = 0
    event_refinements: int = 0
    newton_iterations: int = 0
    factorisations: int = 0
    wall_time_s: float = 0.0
    dt_min_used_s: float = float("inf")
    dt_max_used_s: float = 0.0
    failure_reasons: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "steps": self.steps, "attempts": self.attempts, "cutbacks": self.cutbacks,
            "event_refinements": self.event_refinements, "newton_iterations": self.newton_iterations,
            "factorisations": self.factorisations, "wall_time_s": self.wall_time_s,
            "dt_min_used_s": self.dt_min_used_s, "dt_max_used_s": self.dt_max_used_s,
            "failure_reasons": dict(self.failure_reasons),
        }


class EnergyAccount:
    """Mechanical energy of a state and the work of external loads, for balance checks.

    Energy = 1/2 v.Mv + 1/2 u.Ku (FE) + 1/2 m |zd|^2 (rigid) + penalty energies; the work of FE
    loads and rigid-body forces (incl. gravity) is accumulated with the trapezoidal rule."""

    def __init__(self, system: CoupledSystem):
        self.system = system
        self.work_J = 0.0
        fe = system.fe
        if fe is not None:
            self._x = fe.new_vector()
            self._y = fe.new_vector()
            self._f0 = fe.new_vector()
            self._f1 = fe.new_vector()

    def _quadratic(self, A, arr) -> float:
        n = self.system.n_fe
        self._x.array_w[:] = arr[:n]
        A.mult(self._x, self._y)
        return 0.5 * self._x.dot(self._y)

    def energy_J(self, state: TransientState) -> dict[str, float]:
        sysm = self.system
        out = {"kinetic_fe_J": 0.0, "strain_fe_J": 0.0, "contact_J": 0.0}
        if sysm.fe is not None:
            out["kinetic_fe_J"] = self._quadratic(sysm.fe.M, state.v)
            out["strain_fe_J"] = self._quadratic(sysm.fe.K, state.u)
            for f in sysm.fields:
                f.u_mid.x.array[:] = state.u
            for c in sysm.surface_contacts:
                sl = sysm.rigid.dofs(c.body)
                c.set_body_state(state.z[sl], state.zd[sl])
                out["contact_J"] += c.elastic_energy_J()
        out["kinetic_rigid_J"] = 0.5 * float(np.sum(sysm.rigid.mass_diagonal * state.zd**2))
        for c in sysm.point_contacts:
            lo, up = sysm.rigid.dofs(c.lower), sysm.rigid.dofs(c.upper)
            delta, _ = c.penetration(state.z[lo], state.z[up], state.zd[lo], state.zd[up])
            out["contact_J"] += c.elastic_energy_J(delta)
        out["total_J"] = sum(out.values())
        return out

    def add_work(self, old: TransientState, new: TransientState) -> None:
        sysm = self.system
        dz = (new.z - old.z) * sysm.rigid.free_mask
        f0, f1 = sysm.rigid.external_force_N(old.t), sysm.rigid.external_force_N(new.t)
        self.work_J += 0.5 * float((f0 + f1) @ dz)
        if sysm.fe is not None and sysm.fe.loads:
            n = sysm.n_fe
            sysm.fe.load_N(old.t, self._f0)
            sysm.fe.load_N(new.t, self._f1)
            self._f0.axpy(1.0, self._f1)
            self._x.array_w[:] = (new.u - old.u)[:n]
            self._x.array_w[self.system.fe.bc_local_owned] = 0.0
            self.work_J += 0.5 * self._f0.dot(self._x)


class TimeStepper:
    """Advances a :class:`CoupledSystem` from a state to an end time with adaptive dt.

    ``exports`` are objects with ``write(record)``; each accepted step produces one record (dict
    of time, dt, rigid-body motion, contact forces, optional energies)."""

    def __init__(self, system: CoupledSystem, controller: StepController, exports=(), track_energy=False,
                 progress=None):
        self.system = system
        self.controller = controller
        self.monitor = ContactMonitor(system)
        self.exports = list(exports)
        self.energy = EnergyAccount(system) if track_energy else None
        self.progress = progress
        self.stats = RunStatistics()

    def record(self, state: TransientState, dt: float, forces: dict, status) -> dict:
        rec = {"time_s": state.t, "dt_s": dt, "position_m": state.z.copy(), "velocity_m_per_s": state.zd.copy(),
               "contact_force_N": forces, "contact_closed": np.array(status.closed, dtype=np.int8)}
        if self.energy is not None:
            rec["energy_J"] = self.energy.energy_J(state)
            rec["external_work_J"] = self.energy.work_J
        return rec

    def run(self, state: TransientState, t_end_s: float, on_step=None) -> TransientState:
        ctl, stats = self.controller, self.stats
        start = time.perf_counter()
        status = self.monitor.status(state)
        changed = False
        if self.energy is not None:
            self.energy.initial = self.energy.energy_J(state)
        while state.t < t_end_s * (1 - 1e-12):
            dt = ctl.propose(status, changed)
            while True:
                dt_try = min(dt, t_end_s - state.t)
                stats.attempts += 1
                reason, new_state = self.system.solve_step(state, dt_try)   # loads updated inside
                if new_state is None:                                       # convergence reason
                    stats.failure_reasons[int(reason)] = stats.failure_reasons.get(int(reason), 0) + 1
                    dt = ctl.cut_back(dt_try, f"SNES reason {int(reason)}")
                    continue
                new_status = self.monitor.status(new_state)
                changed = new_status.closed != status.closed
                smaller = ctl.refine_event(dt_try) if changed else None
                if smaller is not None:
                    dt = smaller
                    continue
                break
            forces = self.system.last_forces_N
            if self.energy is not None:
                self.energy.add_work(state, new_state)
            rec = self.record(new_state, dt_try, forces, new_status)
            for export in self.exports:                                     # export
                export.write(rec)
            if on_step is not None:
                on_step(rec)
            state, status = new_state, new_status                           # shift state
            ctl.accepted(dt_try)                                            # adapt dt
            stats.steps += 1
            stats.dt_min_used_s = min(stats.dt_min_used_s, dt_try)
            stats.dt_max_used_s = max(stats.dt_max_used_s, dt_try)
            if self.progress is not None:
                self.progress.update(state.t)
        stats.cutbacks = ctl.cutbacks
        stats.event_refinements = ctl.event_refinements
        stats.newton_iterations = self.system.total_iterations
        stats.factorisations = self.system.cache.factorisations if self.system.cache else 0
        stats.wall_time_s += time.perf_counter() - start
        return state
