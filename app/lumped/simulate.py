"""Run the lumped drill model: initial state, step choice, buffers, energy ledger."""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from app.case.lumped import InitialSection, SolverSection
from app.errors import NumericalFailure
from app.lumped import kernel as K
from app.lumped.model import (
    ICOS,
    ID1,
    IONE,
    IV,
    IVD,
    IW,
    IWD,
    IX,
    IXD,
    IZ,
    IZD,
    LEDGER_NAMES,
    N_STATE,
    Propagators,
    energy_terms,
    penetration_rows,
    shortest_period_s,
)
from app.lumped.outputs import contact_forces_N
from app.lumped.parameters import LumpedParameters


@dataclass
class InitialState:
    """Positions (m) and velocities (m/s) in the model's coordinates; x is the modal coordinate."""

    x_m: float = 0.0
    x_velocity_m_per_s: float = 0.0
    z_m: float = 0.0
    z_velocity_m_per_s: float = 0.0
    w_m: float = 0.0
    w_velocity_m_per_s: float = 0.0
    v_m: float = 0.0
    v_velocity_m_per_s: float = 0.0


def steady_state_vibration(p: LumpedParameters) -> tuple[float, float]:
    """x(0), x'(0) of the free transducer's harmonic steady state under U = U0 sin(omega t) and F_a."""
    omega = p.drive_angular_frequency_rad_per_s
    amplitude = (
        -p.force_factor_N_per_V
        * p.voltage_amplitude_V
        / complex(p.modal_stiffness_N_per_m - p.modal_mass_kg * omega**2, p.modal_damping_N_s_per_m * omega)
    )
    static = -p.downforce_N / p.modal_stiffness_N_per_m
    return static + amplitude.imag, omega * amplitude.real


def initial_state_from_section(p: LumpedParameters, init: InitialSection) -> InitialState:
    x0, xd0 = steady_state_vibration(p) if init.vibration == "steady_state" else (0.0, 0.0)
    return InitialState(
        x_m=x0,
        x_velocity_m_per_s=xd0,
        z_m=init.transducer_z_m,
        z_velocity_m_per_s=init.transducer_velocity_m_per_s,
        w_m=init.free_mass_w_m,
        w_velocity_m_per_s=init.free_mass_velocity_m_per_s,
        v_m=init.stem_v_m,
        v_velocity_m_per_s=init.stem_velocity_m_per_s,
    )


@dataclass
class SimulationResult:
    parameters: LumpedParameters
    step_s: float
    lattice_unit_s: float
    duration_s: float
    samples_t_s: np.ndarray
    samples_y: np.ndarray
    samples_mode: np.ndarray
    events: np.ndarray  # columns: kernel.EV_*
    ledger_J: dict
    impulse_total_N_s: np.ndarray
    final_y: np.ndarray
    final_mode: int
    initial_y: np.ndarray
    counters: dict
    wall_s: dict = field(default_factory=dict)

    def contact_forces_N(self) -> np.ndarray:
        """(n_samples, 3): forces of the closed layers at the samples (0 when open)."""
        return contact_forces_N(self.samples_y, self.samples_mode, self.propagators.force_rows)

    def energy_balance(self) -> dict:
        """Ledger: stored energy change against input minus losses (J)."""
        return energy_balance(self.parameters, self.ledger_J, self.initial_y, self.final_y)


#: the integrator's state arrays and their shapes (a checkpoint of the lumped tier)
STATE_SHAPES = {"y": (N_STATE,), "istate": (K.N_ISTATE,), "fstate": (K.N_FSTATE,), "cflags": (3, 3),
                "initial_y": (N_STATE,), "counts": (3,)}


def state_problem(arrays: dict) -> str | None:
    """Why ``arrays`` are not the state of :class:`LumpedIntegrator` (None: they are)."""
    for name, shape in STATE_SHAPES.items():
        if name not in arrays:
            return f"no state array {name!r}"
        if np.shape(arrays[name]) != shape:
            return f"state array {name!r} has shape {np.shape(arrays[name])}, expected {shape}"
    return None


class LumpedIntegrator:
    """The exact event-driven propagation of eqs. 5-16, resumable in whole output intervals.

    Everything the next call of the kernel depends on is in the state arrays (``y``, ``istate``,
    ``fstate``, ``cflags``): time is an absolute integer lattice (a piece from lattice time T has the
    size of T's lowest set bit, so pieces do not depend on where a call started), and every call ends
    on an output sample, where no piece is under way. So ``advance(a)`` then ``advance(b)`` gives the
    same samples and events, bit for bit, as ``advance(a + b)``, and so does a run restored from
    :meth:`state_arrays` in another process (the propagators are rebuilt deterministically: numba
    loops, no BLAS)."""

    def __init__(self, p: LumpedParameters, output_interval_s: float, initial: InitialState,
                 solver: SolverSection | None = None, propagators: Propagators | None = None):
        self.parameters = p
        self.solver = solver = solver or SolverSection()
        wall0 = _time.perf_counter()
        max_step = shortest_period_s(p) / solver.samples_per_period
        self.sample_every = max(1, math.ceil(output_interval_s / max_step * (1 - 1e-12)))
        self.step_s = output_interval_s / self.sample_every
        self.output_interval_s = output_interval_s
        if propagators is None or propagators.step_s != self.step_s:
            propagators = Propagators(p, self.step_s)
        self.propagators = propagators
        self.unit_s = self.step_s / float(K.UNITS)
        self.wall_setup_s = _time.perf_counter() - wall0
        self.wall_integrate_s = 0.0
        self.intervals = 0            # output intervals done (samples after the one at t = 0)
        self.events_total = 0

        y = np.zeros(N_STATE)
        y[IX], y[IXD] = initial.x_m, initial.x_velocity_m_per_s
        y[IZ], y[IZD] = initial.z_m, initial.z_velocity_m_per_s
        y[IW], y[IWD] = initial.w_m, initial.w_velocity_m_per_s
        y[IV], y[IVD] = initial.v_m, initial.v_velocity_m_per_s
        y[IONE], y[ICOS] = 1.0, 1.0
        pos_rows, _ = penetration_rows()
        mode = 0
        for i in range(3):
            pen = float(pos_rows[i] @ y)
            if pen > 0.0:
                mode |= 1 << i
                y[ID1 + i] = pen
        self.istate = np.zeros(K.N_ISTATE, dtype=np.int64)
        self.fstate = np.zeros(K.N_FSTATE)
        self.fstate[K.F_LAST_SWITCH : K.F_LAST_SWITCH + 3] = -np.inf
        self.cflags = np.zeros((3, 3), dtype=np.int64)
        for i in range(3):
            value = float(propagators.event_value[mode, i] @ y)
            self.cflags[i, K.C_ARMED] = 1 if value > 0.0 else 0
        self.istate[K.S_MODE] = mode
        self.y = y
        self.initial_y = y.copy()
        self.initial_mode = mode

    # ------------------------------------------------------------------ state
    def state_arrays(self) -> dict[str, np.ndarray]:
        """The state a resumed integrator continues from (copies): the kernel's arrays, the first state and
        ``counts`` (output intervals done, events so far, the first contact mode)."""
        out = {name: np.array(getattr(self, name)) for name in STATE_SHAPES if name != "counts"}
        out["counts"] = np.array([self.intervals, self.events_total, self.initial_mode], dtype=np.int64)
        return out

    def restore(self, arrays: dict[str, np.ndarray]) -> None:
        """Continue from :meth:`state_arrays` (checked by :func:`state_problem` first)."""
        for name in STATE_SHAPES:
            if name != "counts":
                setattr(self, name, np.array(arrays[name], dtype=getattr(self, name).dtype))
        self.intervals, self.events_total, self.initial_mode = (int(c) for c in np.asarray(arrays["counts"]))

    @property
    def mode(self) -> int:
        return int(self.istate[K.S_MODE])

    @property
    def lattice_time(self) -> int:
        """Current time in lattice units (h / 2**30)."""
        return int(self.istate[K.S_TIME])

    def time_s(self, intervals: int | None = None) -> float:
        """Lattice time of the sample after ``intervals`` output intervals (now by default) [s], as the
        kernel computes its sample times."""
        n = self.intervals if intervals is None else intervals
        return float(np.float64((n * self.sample_every) << K.LEVELS) * self.unit_s)

    @property
    def counters(self) -> dict:
        return {"events": self.events_total, "zeno_holds": int(self.istate[K.S_ZENO_LOCKS]),
                "grazing_checks_skipped_by_hermite": int(self.istate[K.S_HERMITE_SKIPS]),
                "bisections": int(self.istate[K.S_BISECTIONS])}

    # ------------------------------------------------------------------ stepping
    def advance(self, intervals: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Propagate ``intervals`` output intervals; returns their samples (times [s], states, contact
        modes: one per interval end) and the events in them (rows of columns kernel.EV_*)."""
        n = int(intervals)
        samples_t = np.empty(n)
        samples_y = np.empty((n, N_STATE))
        samples_mode = np.empty(n, dtype=np.int64)
        events = np.empty((max(256, n // 8), K.N_EVCOL))
        if n <= 0:
            return samples_t, samples_y, samples_mode, events[:0]
        time_end_units = ((self.intervals + n) * self.sample_every) << K.LEVELS
        self.istate[K.S_SAMPLES] = 0         # the buffers are this call's: counters restart
        self.istate[K.S_EVENTS] = 0
        pr, solver = self.propagators, self.solver
        wall0 = _time.perf_counter()
        while True:
            status = K.run_kernel(
                pr.expm, pr.ledger, pr.impulse, pr.event_value, pr.event_slope, pr.gap_rows, pr.force_rows,
                pr.velocity_rows, self.y, self.istate, self.fstate, self.cflags, time_end_units,
                self.sample_every, self.unit_s, solver.zeno_window_s, solver.zeno_max_switches,
                samples_t, samples_y, samples_mode, events,
            )
            if status == K.DONE:
                break
            if status == K.EVENTS_FULL:       # the kernel stopped before a piece: continue with more room
                events = np.concatenate([events, np.empty_like(events)])
            else:  # the sample buffer is sized exactly; only reachable through rounding
                raise NumericalFailure(f"lumped model: more samples than the {n} output intervals asked for "
                                       "(lattice rounding)")
        self.wall_integrate_s += _time.perf_counter() - wall0
        if int(self.istate[K.S_SAMPLES]) != n:
            raise NumericalFailure(f"lumped model: {int(self.istate[K.S_SAMPLES])} samples for {n} output intervals")
        if not np.all(np.isfinite(self.y)):
            raise NumericalFailure(
                "lumped model: the state became non-finite although the propagation is exact; "
                "check the parameters (tried: exact matrix-exponential steps, no step-size control to relax)"
            )
        n_events = int(self.istate[K.S_EVENTS])
        self.intervals += n
        self.events_total += n_events
        return samples_t, samples_y, samples_mode, events[:n_events].copy()

    @property
    def ledger_J(self) -> dict:
        return {name: float(self.fstate[K.F_LEDGER + k]) for k, name in enumerate(LEDGER_NAMES)}

    @property
    def impulse_total_N_s(self) -> np.ndarray:
        return self.fstate[K.F_IMPULSE_TOTAL : K.F_IMPULSE_TOTAL + 3].copy()


def energy_balance(p: LumpedParameters, ledger_J: dict, initial_y: np.ndarray, final_y: np.ndarray) -> dict:
    """Ledger: stored energy change against input minus losses (J)."""
    start = energy_terms(p, initial_y)
    end = energy_terms(p, final_y)
    stored_change = sum(end[k] - start[k] for k in start)
    losses = sum(ledger_J[name] for name in LEDGER_NAMES[1:])
    electrical = ledger_J["electrical_input"]
    closure = stored_change - (electrical - losses)
    gravity_work = -(end["gravity_potential_J"] - start["gravity_potential_J"])
    downforce_work = -(end["downforce_potential_J"] - start["downforce_potential_J"])
    # relative to all energy that flowed in or out of the store
    scale = abs(electrical) + losses + abs(gravity_work) + abs(downforce_work)
    if scale == 0.0:
        scale = max(abs(v) for v in list(start.values()) + list(end.values())) or 1.0
    return {
        "electrical_input_J": electrical,
        "modal_damping_loss_J": ledger_J["modal_damping"],
        "contact_tip_ball_loss_J": ledger_J["tip_ball"],
        "contact_ball_stem_loss_J": ledger_J["ball_stem"],
        "contact_stem_rock_loss_J": ledger_J["stem_rock"],
        "gravity_work_J": gravity_work,
        "downforce_work_J": downforce_work,
        "kinetic_change_J": end["kinetic_J"] - start["kinetic_J"],
        "elastic_change_J": end["elastic_J"] - start["elastic_J"],
        "closure_error_J": closure,
        "closure_relative": abs(closure) / scale,
    }


def intervals_in(duration_s: float, output_interval_s: float) -> int:
    """Output intervals of a run of ``duration_s`` (rounded up to whole intervals, at least one)."""
    return max(1, math.ceil(duration_s / output_interval_s * (1 - 1e-12)))


def simulate(
    p: LumpedParameters,
    duration_s: float,
    initial: InitialState,
    output_interval_s: float,
    solver: SolverSection | None = None,
    propagators: Propagators | None = None,
) -> SimulationResult:
    """Integrate eqs. 5-16 from ``initial`` over ``duration_s`` (rounded up to whole output intervals)
    in memory, in one call of :class:`LumpedIntegrator` (the run loop's engine, app/lumped/engine.py,
    advances the same integrator in chunks)."""
    integrator = LumpedIntegrator(p, output_interval_s, initial, solver, propagators)
    n_intervals = intervals_in(duration_s, output_interval_s)
    t, y, mode, events = integrator.advance(n_intervals)
    result = SimulationResult(
        parameters=p,
        step_s=integrator.step_s,
        lattice_unit_s=integrator.unit_s,
        duration_s=n_intervals * output_interval_s,
        samples_t_s=np.concatenate([[0.0], t]),
        samples_y=np.concatenate([integrator.initial_y[None, :], y]),
        samples_mode=np.concatenate([[integrator.initial_mode], mode]),
        events=events,
        ledger_J=integrator.ledger_J,
        impulse_total_N_s=integrator.impulse_total_N_s,
        final_y=integrator.y.copy(),
        final_mode=integrator.mode,
        initial_y=integrator.initial_y,
        counters=integrator.counters,
        wall_s={"setup": integrator.wall_setup_s, "integrate": integrator.wall_integrate_s},
    )
    result.propagators = integrator.propagators
    return result


def tip_displacement_m(y: np.ndarray) -> np.ndarray:
    return y[..., IX] + y[..., IZ]


__all__ = [
    "InitialState",
    "SimulationResult",
    "simulate",
    "steady_state_vibration",
    "initial_state_from_section",
    "tip_displacement_m",
    "IVD",
    "IWD",
    "IZD",
]
