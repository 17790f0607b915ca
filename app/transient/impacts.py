"""Generic statistics of a transient run (FE and modal tiers), read from its HDF5 time series, under
the keys the lumped tier reports too (app/lumped/stats.py), so the tiers compare line by line.
What belongs to one scene (the drill's transducer flights) is in that scene (app/scenes/), added by the runner.

- every contact: impacts (open -> closed transitions) and their rate per second;
- a contact whose lower body is fixed (the rock foundation): impulse per impact, mean force, and
  the mean power delivered into it, P = (1/T) integral f d(delta) (f the contact force, delta the
  penetration), which over closed intervals is the energy the foundation absorbs;
- every free rigid body: its largest rise above its start and its RMS velocity.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app import series as S
from app.series import read_time_series


def closed_intervals(closed: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) row of every run of closed rows (closed is 0/1 per row)."""
    flag = np.concatenate([[0], (np.asarray(closed) > 0).astype(np.int8), [0]])
    edges = np.diff(flag)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def period_average(t_s: np.ndarray, x: np.ndarray, period_s: float, samples_per_period: int = 32):
    """(t, mean of x over the drive period centred at t) on a uniform grid of period / samples."""
    h = period_s / samples_per_period
    if t_s[-1] - t_s[0] < 2 * period_s:
        return t_s, x
    grid = np.arange(t_s[0], t_s[-1], h)
    values = np.interp(grid, t_s, x)
    kernel = np.ones(samples_per_period) / samples_per_period
    mean = np.convolve(values, kernel, mode="valid")
    centre = grid[: mean.size] + 0.5 * (samples_per_period - 1) * h
    return centre, mean


def statistics_from_file(h5_path: Path, case) -> tuple[dict, dict]:
    """(:func:`contact_summary`, :func:`run_statistics`) of the time series in ``h5_path`` of a run of
    ``case`` (rank 0 only)."""
    data = read_time_series(h5_path)
    cfg = case.transient
    return contact_summary(data, [c.name for c in cfg.contacts]), run_statistics(data, cfg)


def contact_summary(data: dict[str, np.ndarray], names: list[str]) -> dict:
    """Per contact: impacts (open -> closed transitions; closed at the first step is no impact, as
    in :func:`run_statistics`), largest force [N], impulse sum |f| dt [N s] and time closed [s]."""
    if S.TIME not in data or not data[S.TIME].size:
        return {}
    dt = data[S.STEP]
    out = {}
    for name in names:
        force = np.linalg.norm(data[S.contact_force(name)], axis=1)
        closed = data[S.contact_closed(name)]
        impacts = int(np.sum(np.diff((closed > 0).astype(np.int8)) == 1))
        out[name] = {"impacts": impacts, "max_force_N": float(force.max()), "impulse_N_s": float(np.sum(force * dt)),
                     "closed_time_s": float(np.sum(dt * (closed > 0)))}
        if S.contact_peak_pressure(name) in data:         # output.contact_pressure (FE tier, surface contacts)
            out[name]["max_pressure_Pa"] = float(data[S.contact_peak_pressure(name)].max())
    return out


def run_statistics(data: dict[str, np.ndarray], cfg) -> dict:
    """Generic statistics of a transient run: ``data`` holds the time series by name (one row per step,
    app/series.py names), ``cfg`` is the case's [transient] section. A scene's own statistics are added by
    the runner (app/scenes/)."""
    if S.TIME not in data or data[S.TIME].shape[0] < 2:
        return {}
    t = data[S.TIME]
    dt = data[S.STEP] if S.STEP in data else np.diff(t, prepend=t[0])
    # the first row is the state after the first step dt[0]: the run spans t[0] - dt[0] .. t[-1], the
    # span the sums of f dt cover
    duration = float(t[-1] - t[0] + dt[0])
    stats: dict = {"simulated_time_s": duration}
    fixed = {b.name for b in cfg.bodies if b.fixed}
    counts, rates = {}, {}
    for c in cfg.contacts:
        closed = data[S.contact_closed(c.name)]
        intervals = closed_intervals(closed)
        impacts = sum(1 for a, _ in intervals if a > 0)     # closed from the first step: no impact
        counts[c.name] = impacts
        rates[c.name] = impacts / duration
        if c.kind == "point" and c.lower in fixed:
            force = np.linalg.norm(data[S.contact_force(c.name)], axis=1)
            normal = np.asarray(c.direction, dtype=float) / np.linalg.norm(c.direction)
            # The recorded force acts at the step's generalised mid-point; the work it does is
            # f . d(delta) per step (the scheme's own energy pairing), with d(delta) = -n . dz.
            penetration_step = -np.diff(data[S.body_position(c.upper)] @ normal, prepend=np.nan)
            penetration_step[0] = 0.0
            # per impact: both means divide by the impact count (a closure from the start is none)
            impulses = [float(np.sum(force[a:b + 1] * dt[a:b + 1])) for a, b in intervals if a > 0]
            work = float(np.sum(force * penetration_step))
            stats[f"{c.name}_foundation"] = {
                "impulse_per_impact_mean_N_s": float(np.mean(impulses)) if impulses else 0.0,
                "impulse_per_impact_max_N_s": float(np.max(impulses)) if impulses else 0.0,
                "mean_force_N": float(np.sum(force * dt)) / duration,
                "mean_power_W": work / duration,
                "energy_per_impact_mean_J": work / impacts if impacts else 0.0,
                "peak_force_N": float(force.max()),
            }
    stats["impact_count"] = counts
    stats["impact_rate_per_s"] = rates

    bodies = {}
    for b in cfg.bodies:
        if b.fixed or S.body_position(b.name) not in data:
            continue
        z = data[S.body_position(b.name)][:, -1]
        v = data[S.body_velocity(b.name)][:, -1]
        bodies[b.name] = {"max_rise_m": float(z.max() - z[0]),
                          "rms_velocity_m_per_s": float(np.sqrt(np.trapz(v**2, t) / duration))}
    stats["bodies"] = bodies
    return stats
