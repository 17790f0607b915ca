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
    linear_steps: int = 0
    factorisations: int = 0
    wall_time_s: float = 0.0
    dt_min_used_s: float = float("inf")
    dt_max_used_s: float = 0.0
    failure_reasons: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "steps": self.steps, "attempts": self.attempts, "cutbacks": self.cutbacks,
            "event_refinements": self.event_refinements, "newton_iterations": self.newton_iterations,
            "linear_steps": self.linear_steps,
            "factorisations": self.factorisations, "wall_time_s": self.wall_time_s,
            "dt_min_used_s": self.dt_min_used_s, "dt_max_used_s": self.dt_max_used_s,
            "failure_reasons": dict(self.failure_reasons),
        }


class EnergyAccount:
    """Mechanical energy of a state and the work of external loads, for balance checks.

    Energy = 1/2 v.Mv + 1/2 u.Ku (FE) + 1/2 m |zd|^2 + 1/2 J omega^2 (rigid) + penalty energies; the work of FE
    loads and rigid-body forces (incl. gravity and brakes, whose work is negative) is
    accumulated with the trapezoidal rule."""

    def __init__(self, system: CoupledSystem):
        self.system = system
        self.work_J = 0.0
        self.damping_J = 0.0
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
        for c in sysm.interactions:
            out["contact_J"] += c.stored_energy_J(sysm, state)
        out["kinetic_rigid_J"] = 0.5 * float(np.sum(sysm.rigid.mass_diagonal * state.zd**2))
        out["total_J"] = sum(out.values())
        return out

    def add_work(self, old: TransientState, new: TransientState) -> None:
        """The external loads' work over a step (trapezoidal) and the structure's damping loss,
        dt vm.C vm with vm = (v_old + v_new) / 2 (the discrete loss of average acceleration)."""
        sysm = self.system
        if sysm.fe is not None and sysm.fe.C is not None:
            n = sysm.n_fe
            self._x.array_w[:] = 0.5 * (old.v[:n] + new.v[:n])
            sysm.fe.C.mult(self._x, self._y)
            self.damping_J += (new.t - old.t) * self._x.dot(self._y)
        dz = (new.z - old.z) * sysm.rigid.free_mask
        f0 = sysm.rigid.external_force_N(old.t) + sysm.rigid.brake_force_N(old.zd)
        f1 = sysm.rigid.external_force_N(new.t) + sysm.rigid.brake_force_N(new.zd)
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
    """Advances a :class:`CoupledSystem` one accepted step at a time with adaptive dt (:meth:`step`), in
    FESTIM's ``iterate()`` order: update loads (inside the solve, at the step's own times) -> solve -> check
    the convergence reason (a failure cuts dt back and retries; a contact change inside a too-long step
    refines it) -> export (the caller, with the returned record) -> shift the state -> adapt dt.

    The run loop of a case (app/loop/loop.py) calls :meth:`step` through the FE engine
    (app/transient/engine.py); :meth:`run` steps in memory for the demos and tests."""

    def __init__(self, system: CoupledSystem, controller: StepController, track_energy=False):
        self.system = system
        self.controller = controller
        self.monitor = ContactMonitor(system)
        self.energy = EnergyAccount(system) if track_energy else None
        self.stats = RunStatistics()
        self.changed = False                # did the last accepted step change the contact set?
        self.status = None                  # contact status of the current state
        # energy each interaction has dissipated since t = 0 [J]: its damping and friction power,
        # evaluated where the scheme evaluates forces (the step's generalised mid-point), integrated
        # by the trapezoidal rule between accepted steps (the first step: its own power)
        self.dissipated_J = {c.name: 0.0 for c in system.interactions}
        self.dissipation_W: dict[str, float] = {}
        self._factorisations_before = 0     # factorisations of the run before a resume
        self._wall_start = None

    def record(self, state: TransientState, dt: float, forces: dict, status) -> dict:
        rec = {"time_s": state.t, "dt_s": dt, "position_m": state.z.copy(), "velocity_m_per_s": state.zd.copy(),
               "contact_force_N": forces, "contact_closed": np.array(status.closed, dtype=np.int8),
               "dissipated_J": dict(self.dissipated_J)}
        if self.energy is not None:
            rec["energy_J"] = self.energy.energy_J(state)
            rec["external_work_J"] = self.energy.work_J
            rec["damping_dissipated_J"] = self.energy.damping_J
        return rec

    # ------------------------------------------------------------ checkpoints
    def snapshot(self) -> dict:
        """Everything besides the state that the next steps depend on (JSON-able): the controller's
        cap and counters, whether the last step changed the contact set, and the statistics."""
        self._finish_statistics()
        ctl, stats = self.controller, self.stats
        return {"changed": bool(self.changed), "controller": ctl.snapshot(),
                "newton_iterations": self.system.total_iterations,
                "linear_steps": self.system.linear_steps,
                "factorisations": self._factorisations(),
                "dissipated_J": dict(self.dissipated_J), "dissipation_W": dict(self.dissipation_W),
                "statistics": {k: v for k, v in stats.as_dict().items() if k not in _DERIVED},
                "failure_reasons": {str(k): v for k, v in stats.failure_reasons.items()},
                "energy": ({"work_J": self.energy.work_J, "damping_J": self.energy.damping_J}
                           if self.energy is not None else None)}

    def restore(self, snap: dict) -> None:
        ctl, stats = self.controller, self.stats
        self.changed = bool(snap["changed"])
        ctl.restore(snap["controller"])
        self.system.total_iterations = int(snap["newton_iterations"])
        self.system.linear_steps = int(snap.get("linear_steps", 0))
        self._factorisations_before = int(snap["factorisations"])
        self.dissipated_J.update({k: float(v) for k, v in snap.get("dissipated_J", {}).items()})
        self.dissipation_W = {k: float(v) for k, v in snap.get("dissipation_W", {}).items()}
        for key, value in snap["statistics"].items():
            setattr(stats, key, value)
        stats.failure_reasons = {int(k): v for k, v in snap["failure_reasons"].items()}
        if self.energy is not None and snap.get("energy"):
            self.energy.work_J = float(snap["energy"]["work_J"])
            self.energy.damping_J = float(snap["energy"]["damping_J"])

    def _factorisations(self) -> int:
        cache = self.system.cache
        return self._factorisations_before + (cache.factorisations if cache else 0)

    def _step_size(self, dt: float, t: float, t_end_s: float) -> float:
        """dt, or the remainder to t_end_s; a remainder within round-off of dt is dt itself (a
        time reached by summing steps must not produce a sliver step or a new factorisation)."""
        remainder = t_end_s - t
        return dt if remainder >= dt * (1 - 1e-9) else remainder

    def begin(self, state: TransientState) -> None:
        """Before the first step from ``state`` (a start or a resume): its contact status, the energy
        account's start."""
        self.status = self.monitor.status(state)
        if self.energy is not None:
            self.energy.initial = self.energy.energy_J(state)
        self._wall_start = time.perf_counter()

    def step(self, state: TransientState, t_end_s: float) -> tuple[TransientState, dict]:
        """One accepted step from ``state`` towards ``t_end_s``: (new state, its record)."""
        ctl, stats = self.controller, self.stats
        if self.status is None:
            self.begin(state)
        status = self.status
        dt = ctl.propose(status, self.changed)
        while True:
            dt_try = self._step_size(dt, state.t, t_end_s)
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
        for name, power in self.system.last_dissipation_W.items():
            self.dissipated_J[name] += 0.5 * dt_try * (self.dissipation_W.get(name, power) + power)
        self.dissipation_W = dict(self.system.last_dissipation_W)
        if self.energy is not None:
            self.energy.add_work(state, new_state)
        rec = self.record(new_state, dt_try, forces, new_status)
        self.status, self.changed = new_status, changed                 # shift state
        ctl.accepted(dt_try)                                            # adapt dt
        stats.steps += 1
        stats.dt_min_used_s = min(stats.dt_min_used_s, dt_try)
        stats.dt_max_used_s = max(stats.dt_max_used_s, dt_try)
        return new_state, rec

    def run(self, state: TransientState, t_end_s: float, on_step=None) -> TransientState:
        """Step from ``state`` to ``t_end_s`` in memory, calling ``on_step(record)`` after each step."""
        self.begin(state)
        while state.t < t_end_s * (1 - 1e-12):
            state, rec = self.step(state, t_end_s)
            if on_step is not None:
                on_step(rec)
        self._finish_statistics()
        return state

    def _finish_statistics(self) -> None:
        """Bring the counters in ``stats`` up to date (adds the wall time since the last call)."""
        ctl, stats = self.controller, self.stats
        stats.cutbacks = ctl.cutbacks
        stats.event_refinements = ctl.event_refinements
        stats.newton_iterations = self.system.total_iterations
        stats.linear_steps = self.system.linear_steps
        stats.factorisations = self._factorisations()
        now = time.perf_counter()
        if self._wall_start is not None:
            stats.wall_time_s += now - self._wall_start
        self._wall_start = now


_DERIVED = ("failure_reasons",)


def run_scene(system, state, sizes, t_end_s: float, track_energy=False):
    """Step ``system`` from ``state`` to ``t_end_s`` with step sizes ``sizes`` (StepSizes) in memory and return
    (records of every accepted step, final state, the stepper with its statistics)."""
    records = []
    stepper = TimeStepper(system, StepController(sizes), track_energy=track_energy)
    final = stepper.run(state, t_end_s, on_step=records.append)
    return records, final, stepper
