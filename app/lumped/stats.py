"""Statistics of a lumped run: impacts, what reaches the rock, transducer flights, free-mass activity."""

from __future__ import annotations

import numpy as np

from app.lumped import kernel as K
from app.lumped.model import ID3, IW, IWD, IZ
from app.lumped.parameters import CONTACT_NAMES
from app.lumped.simulate import SimulationResult


def open_intervals(events: np.ndarray, contact: int, initially_closed: bool, end_s: float):
    """(start, end, start_row) of every open interval of ``contact``; the last may end at end_s."""
    rows = np.nonzero(events[:, K.EV_CONTACT] == contact)[0]
    intervals = []
    open_since, open_row = (None, -1) if initially_closed else (0.0, -1)
    for r in rows:
        if events[r, K.EV_CLOSING] == 0.0:
            open_since, open_row = events[r, K.EV_TIME], r
        elif open_since is not None:
            intervals.append((open_since, events[r, K.EV_TIME], open_row, False))
            open_since = None
    if open_since is not None:
        intervals.append((open_since, end_s, open_row, True))
    return intervals


def flight_statistics(result: SimulationResult, min_rise_m: float, bins: int) -> dict:
    """Transducer flights: tip/free-mass contact open intervals in which z rises at least ``min_rise_m``.

    While that contact is open the rigid coordinate moves on z'' = -(g + F_a / m_t), so the rise of a
    flight is max(z', 0)^2 / (2 a) at take-off and its apex z + rise (exact, not sampled). The
    20 kHz hammering of the tip on the ball opens the contact for tens of microseconds with rises of
    nanometres to micrometres; a rise threshold separates those from flights one could film."""
    p = result.parameters
    accel = p.gravity_m_per_s2 + p.downforce_N / p.transducer_mass_kg
    intervals = open_intervals(result.events, 0, bool(result.samples_mode[0] & 1), result.duration_s)
    durations, apexes, censored = [], [], 0
    starts = []
    for start, end, row, ends_at_end in intervals:
        if row < 0 or accel <= 0:
            continue  # open from the start: no take-off
        z0, zd0 = result.events[row, K.EV_Z], result.events[row, K.EV_ZDOT]
        rise = max(zd0, 0.0) ** 2 / (2.0 * accel)
        if rise < min_rise_m:
            continue
        if ends_at_end:
            censored += 1
            continue
        durations.append(end - start)
        apexes.append(z0 + rise)
        starts.append(start)
    durations = np.asarray(durations)
    apexes = np.asarray(apexes)
    counts, edges = (
        np.histogram(durations, bins=bins) if len(durations) else (np.zeros(bins, int), np.zeros(bins + 1))
    )
    half = 0.5 * result.duration_s
    starts = np.asarray(starts)
    return {
        "flight_count": int(len(durations)),
        "flight_rate_per_s": len(durations) / result.duration_s,
        "flight_duration_mean_s": float(durations.mean()) if len(durations) else 0.0,
        "flight_duration_std_s": float(durations.std()) if len(durations) else 0.0,
        "flight_duration_cv": float(durations.std() / durations.mean()) if len(durations) > 1 else 0.0,
        "flight_duration_histogram": {"bin_edges_s": edges.tolist(), "counts": counts.tolist()},
        "flight_apex_mean_m": float(apexes.mean()) if len(apexes) else 0.0,
        "flight_apex_max_m": float(apexes.max()) if len(apexes) else 0.0,
        "flight_count_first_half": int(np.sum(starts < half)) if len(starts) else 0,
        "flight_count_second_half": int(np.sum(starts >= half)) if len(starts) else 0,
        "flights_still_open_at_end": censored,
        "min_flight_rise_m": min_rise_m,
    }


def run_statistics(result: SimulationResult, min_flight_rise_m: float = 50e-6, bins: int = 20) -> dict:
    p = result.parameters
    ev = result.events
    duration = result.duration_s
    t, y = result.samples_t_s, result.samples_y
    closing = ev[:, K.EV_CLOSING] == 1.0
    stats: dict = {"simulated_time_s": duration}
    n_closings = [int(np.sum(closing & (ev[:, K.EV_CONTACT] == c))) for c in range(3)]
    stats["impact_rate_per_s"] = {name: n / duration for name, n in zip(CONTACT_NAMES, n_closings)}
    stats["impact_count"] = dict(zip(CONTACT_NAMES, n_closings))

    # What reaches the rock: impulse of each stem/rock contact interval, work done on the rock layer.
    rock_open = ev[(ev[:, K.EV_CONTACT] == 2) & ~closing]
    impulses = rock_open[:, K.EV_IMPULSE]
    rock_stiffness = p.contacts[2].stiffness_N_per_m
    rock_work = result.ledger_J["stem_rock"] + 0.5 * rock_stiffness * (
        result.final_y[ID3] ** 2 - result.initial_y[ID3] ** 2
    )
    n_rock = max(n_closings[2], 1)
    forces = result.contact_forces_N()
    stats["rock"] = {
        "impulse_per_impact_mean_N_s": float(impulses.mean()) if len(impulses) else 0.0,
        "impulse_per_impact_max_N_s": float(impulses.max()) if len(impulses) else 0.0,
        "energy_per_impact_mean_J": rock_work / n_rock,
        "mean_power_W": rock_work / duration,
        "mean_force_N": float(result.impulse_total_N_s[2] / duration),
        "static_load_N": (p.transducer_mass_kg + p.free_mass_kg + p.stem_mass_kg) * p.gravity_m_per_s2
        + p.downforce_N,
        "peak_force_at_samples_N": float(forces[:, 2].max()) if len(forces) else 0.0,
    }

    # Transducer: highest rigid position and flights.
    flights = flight_statistics(result, min_flight_rise_m, bins)
    stats["transducer"] = {
        "max_flight_height_m": float(max(np.max(y[:, IZ]), flights["flight_apex_max_m"])),
        "max_flight_height_first_half_m": float(np.max(y[t < duration / 2, IZ])),
        "max_flight_height_second_half_m": float(np.max(y[t >= duration / 2, IZ])),
        **flights,
    }
    ball_impacts = n_closings[0] + n_closings[1]
    stats["free_mass"] = {
        "impact_rate_per_s": ball_impacts / duration,
        "rms_velocity_m_per_s": float(np.sqrt(np.mean(y[:, IWD] ** 2))),
        "max_height_m": float(np.max(y[:, IW])),
    }
    return stats
