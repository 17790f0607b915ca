"""Run the lumped drill model: initial state, step choice, buffers, energy ledger."""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from app.case.lumped import InitialSection, SolverSection
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
        forces = self.samples_y @ self._force_rows.T
        closed = (self.samples_mode[:, None] >> np.arange(3)[None, :]) & 1
        return forces * closed

    def energy_balance(self) -> dict:
        """Ledger: stored energy change against input minus losses (J)."""
        p = self.parameters
        start = energy_terms(p, self.initial_y)
        end = energy_terms(p, self.final_y)
        stored_change = sum(end[k] - start[k] for k in start)
        losses = sum(self.ledger_J[name] for name in LEDGER_NAMES[1:])
        electrical = self.ledger_J["electrical_input"]
        closure = stored_change - (electrical - losses)
        gravity_work = -(end["gravity_potential_J"] - start["gravity_potential_J"])
        downforce_work = -(end["downforce_potential_J"] - start["downforce_potential_J"])
        # relative to all energy that flowed in or out of the store
        scale = abs(electrical) + losses + abs(gravity_work) + abs(downforce_work)
        if scale == 0.0:
            scale = max(abs(v) for v in list(start.values()) + list(end.values())) or 1.0
        return {
            "electrical_input_J": electrical,
            "modal_damping_loss_J": self.ledger_J["modal_damping"],
            "contact_tip_ball_loss_J": self.ledger_J["tip_ball"],
            "contact_ball_stem_loss_J": self.ledger_J["ball_stem"],
            "contact_stem_rock_loss_J": self.ledger_J["stem_rock"],
            "gravity_work_J": gravity_work,
            "downforce_work_J": downforce_work,
            "kinetic_change_J": end["kinetic_J"] - start["kinetic_J"],
            "elastic_change_J": end["elastic_J"] - start["elastic_J"],
            "closure_error_J": closure,
            "closure_relative": abs(closure) / scale,
        }


def simulate(
    p: LumpedParameters,
    duration_s: float,
    initial: InitialState,
    output_interval_s: float,
    solver: SolverSection | None = None,
    propagators: Propagators | None = None,
) -> SimulationResult:
    """Integrate eqs. 5-16 from ``initial`` over ``duration_s`` (rounded up to whole output intervals)."""
    solver = solver or SolverSection()
    wall0 = _time.perf_counter()
    max_step = shortest_period_s(p) / solver.samples_per_period
    sample_every = max(1, math.ceil(output_interval_s / max_step * (1 - 1e-12)))
    step = output_interval_s / sample_every
    if propagators is None or propagators.step_s != step:
        propagators = Propagators(p, step)
    wall_setup = _time.perf_counter() - wall0

    n_intervals = max(1, math.ceil(duration_s / output_interval_s * (1 - 1e-12)))
    time_end_units = (n_intervals * sample_every) << K.LEVELS
    unit_s = step / float(K.UNITS)

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

    istate = np.zeros(K.N_ISTATE, dtype=np.int64)
    fstate = np.zeros(K.N_FSTATE)
    fstate[K.F_LAST_SWITCH : K.F_LAST_SWITCH + 3] = -np.inf
    cflags = np.zeros((3, 3), dtype=np.int64)
    for i in range(3):
        value = float(propagators.event_value[mode, i] @ y)
        cflags[i, K.C_ARMED] = 1 if value > 0.0 else 0
    istate[K.S_MODE] = mode
    initial_y = y.copy()

    n_total_samples = n_intervals + 1
    samples_t = np.empty(n_total_samples)
    samples_y = np.empty((n_total_samples, N_STATE))
    samples_mode = np.empty(n_total_samples, dtype=np.int64)
    samples_t[0], samples_y[0], samples_mode[0] = 0.0, y, mode
    istate[K.S_SAMPLES] = 1
    events = np.empty((max(1024, int(duration_s * 20000)), K.N_EVCOL))

    wall1 = _time.perf_counter()
    while True:
        status = K.run_kernel(
            propagators.expm,
            propagators.ledger,
            propagators.impulse,
            propagators.event_value,
            propagators.event_slope,
            propagators.gap_rows,
            propagators.force_rows,
            propagators.velocity_rows,
            y,
            istate,
            fstate,
            cflags,
            time_end_units,
            sample_every,
            unit_s,
            solver.zeno_window_s,
            solver.zeno_max_switches,
            samples_t,
            samples_y,
            samples_mode,
            events,
        )
        if status == K.DONE:
            break
        if status == K.EVENTS_FULL:
            events = np.concatenate([events, np.empty_like(events)])
        else:  # the sample buffer is sized exactly; only reachable through rounding
            extra = max(16, samples_t.shape[0] // 4)
            samples_t = np.concatenate([samples_t, np.empty(extra)])
            samples_y = np.concatenate([samples_y, np.empty((extra, N_STATE))])
            samples_mode = np.concatenate([samples_mode, np.empty(extra, dtype=np.int64)])
    wall_integrate = _time.perf_counter() - wall1

    n_samples = int(istate[K.S_SAMPLES])
    ledger = {name: float(fstate[K.F_LEDGER + k]) for k, name in enumerate(LEDGER_NAMES)}
    result = SimulationResult(
        parameters=p,
        step_s=step,
        lattice_unit_s=unit_s,
        duration_s=n_intervals * output_interval_s,
        samples_t_s=samples_t[:n_samples].copy(),
        samples_y=samples_y[:n_samples].copy(),
        samples_mode=samples_mode[:n_samples].copy(),
        events=events[: int(istate[K.S_EVENTS])].copy(),
        ledger_J=ledger,
        impulse_total_N_s=fstate[K.F_IMPULSE_TOTAL : K.F_IMPULSE_TOTAL + 3].copy(),
        final_y=y.copy(),
        final_mode=int(istate[K.S_MODE]),
        initial_y=initial_y,
        counters={
            "events": int(istate[K.S_EVENTS]),
            "zeno_holds": int(istate[K.S_ZENO_LOCKS]),
            "grazing_checks_skipped_by_hermite": int(istate[K.S_HERMITE_SKIPS]),
            "bisections": int(istate[K.S_BISECTIONS]),
        },
        wall_s={"setup": wall_setup, "integrate": wall_integrate},
    )
    result._force_rows = propagators.force_rows
    result.propagators = propagators
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
