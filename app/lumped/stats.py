"""Statistics of a lumped run under the keys of every tier (app/transient/impacts.py): impacts per
contact, what reaches the rock (``stem_rock_foundation``), the free bodies' rise and RMS velocity;
the scene's statistics (the drill's transducer flights) come from the written series and event table
(app/scenes/). Exact: from the event table and the integrator's ledger, not the samples, except where
a key says so. The same functions serve the run loop (the series read back from its file) and an
in-memory run (:func:`run_statistics`)."""

from __future__ import annotations

import numpy as np

from app import series as S
from app.lumped import kernel as K
from app.lumped.model import ID3
from app.lumped.outputs import PLOTTED_BODIES, series_rows
from app.lumped.parameters import CONTACT_NAMES, LumpedParameters
from app.lumped.simulate import SimulationResult


def open_intervals(events: np.ndarray, contact: int, initially_closed: bool, end_s: float):
    """(start, end, start_row, ends_at_end) of every open interval of ``contact``; the last may end at end_s."""
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


def statistics(data: dict[str, np.ndarray], events: np.ndarray, p: LumpedParameters, ledger_J: dict,
               impulse_total_N_s: np.ndarray, initial_y: np.ndarray, final_y: np.ndarray, duration_s: float) -> dict:
    """The generic statistics of a run: ``data`` its time series (app/lumped/outputs.py names), ``events``
    its event table, the integrator's ledger [J], total impulse per contact [N s], first and last state."""
    ev = events
    closing = ev[:, K.EV_CLOSING] == 1.0
    stats: dict = {"simulated_time_s": duration_s}
    n_closings = [int(np.sum(closing & (ev[:, K.EV_CONTACT] == c))) for c in range(3)]
    stats["impact_rate_per_s"] = {name: n / duration_s for name, n in zip(CONTACT_NAMES, n_closings)}
    stats["impact_count"] = dict(zip(CONTACT_NAMES, n_closings))

    # What reaches the rock: impulse of each stem/rock contact interval, work done on the rock layer.
    rock_open = ev[(ev[:, K.EV_CONTACT] == 2) & ~closing]
    impulses = rock_open[:, K.EV_IMPULSE]
    rock_stiffness = p.contacts[2].stiffness_N_per_m
    rock_work = ledger_J["stem_rock"] + 0.5 * rock_stiffness * (final_y[ID3] ** 2 - initial_y[ID3] ** 2)
    n_rock = max(n_closings[2], 1)
    rock_force = np.asarray(data[S.contact_force("stem_rock")]).reshape(-1)
    stats["stem_rock_foundation"] = {
        "impulse_per_impact_mean_N_s": float(impulses.mean()) if len(impulses) else 0.0,
        "impulse_per_impact_max_N_s": float(impulses.max()) if len(impulses) else 0.0,
        "energy_per_impact_mean_J": rock_work / n_rock,
        "mean_power_W": rock_work / duration_s,
        "mean_force_N": float(impulse_total_N_s[2] / duration_s),
        "static_load_N": (p.transducer_mass_kg + p.free_mass_kg + p.stem_mass_kg) * p.gravity_m_per_s2
        + p.downforce_N,
        "peak_force_N": float(rock_force.max()) if len(rock_force) else 0.0,       # at the samples
    }

    # Free bodies: largest rise above the start and RMS velocity (uniform samples), as the FE tier.
    stats["bodies"] = {}
    for body in PLOTTED_BODIES:
        z = np.asarray(data[S.body_position(body)]).reshape(-1)
        v = np.asarray(data[S.body_velocity(body)]).reshape(-1)
        stats["bodies"][body] = {"max_rise_m": float(np.max(z) - z[0]),
                                 "rms_velocity_m_per_s": float(np.sqrt(np.mean(v ** 2)))}
    return stats


def contact_summary(data: dict[str, np.ndarray], events: np.ndarray, impulse_total_N_s: np.ndarray,
                    duration_s: float) -> dict:
    """Per contact, under the FE tier's keys (app/transient/impacts.py ``contact_summary``): impacts (closing
    events), largest force at the samples [N], impulse [N s] and time closed [s] (exact: the integrator's
    impulse and the event times)."""
    out = {}
    for i, name in enumerate(CONTACT_NAMES):
        force = np.abs(np.asarray(data[S.contact_force(name)]).reshape(-1))
        closed = np.asarray(data[S.contact_closed(name)]).reshape(-1)
        initially_closed = bool(closed.size and closed[0] > 0)
        open_time = sum(end - start for start, end, _, _ in open_intervals(events, i, initially_closed, duration_s))
        impacts = int(np.sum((events[:, K.EV_CONTACT] == i) & (events[:, K.EV_CLOSING] == 1.0)))
        out[name] = {"impacts": impacts, "max_force_N": float(force.max()) if force.size else 0.0,
                     "impulse_N_s": float(impulse_total_N_s[i]), "closed_time_s": float(duration_s - open_time)}
    return out


def run_statistics(result: SimulationResult) -> dict:
    """:func:`statistics` of an in-memory run (app/lumped/driver.py ``compute``)."""
    data = series_rows(result.samples_t_s, result.samples_y, result.samples_mode, result.propagators.force_rows,
                       result.samples_t_s[0])
    return statistics(data, result.events, result.parameters, result.ledger_J, result.impulse_total_N_s,
                      result.initial_y, result.final_y, result.duration_s)
