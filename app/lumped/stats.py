"""Statistics of a lumped run under the keys of every tier (app/transient/impacts.py): impacts per
contact, what reaches the rock (``stem_rock_foundation``), the free bodies' rise and RMS velocity,
the scene's statistics (the drill's transducer flights) come from the written series and event table
(app/scenes/). Exact: from the event table, not the samples, except where a key says so."""

from __future__ import annotations

import numpy as np

from app.lumped import kernel as K
from app.lumped.model import ID3
from app.lumped.outputs import BODIES, PLOTTED_BODIES
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


def run_statistics(result: SimulationResult) -> dict:
    p = result.parameters
    ev = result.events
    duration = result.duration_s
    y = result.samples_y
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
    stats["stem_rock_foundation"] = {
        "impulse_per_impact_mean_N_s": float(impulses.mean()) if len(impulses) else 0.0,
        "impulse_per_impact_max_N_s": float(impulses.max()) if len(impulses) else 0.0,
        "energy_per_impact_mean_J": rock_work / n_rock,
        "mean_power_W": rock_work / duration,
        "mean_force_N": float(result.impulse_total_N_s[2] / duration),
        "static_load_N": (p.transducer_mass_kg + p.free_mass_kg + p.stem_mass_kg) * p.gravity_m_per_s2
        + p.downforce_N,
        "peak_force_N": float(forces[:, 2].max()) if len(forces) else 0.0,       # at the samples
    }

    # Free bodies: largest rise above the start and RMS velocity (uniform samples), as the FE tier.
    stats["bodies"] = {
        body: {"max_rise_m": float(np.max(y[:, i]) - y[0, i]),
               "rms_velocity_m_per_s": float(np.sqrt(np.mean(y[:, i_dot] ** 2)))}
        for body, (i, i_dot, _) in BODIES.items() if body in PLOTTED_BODIES
    }
    return stats
