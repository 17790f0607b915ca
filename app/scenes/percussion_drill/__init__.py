"""Report of the percussion drill (``scene = "percussion-drill"``; the lumped tier is this model): the
transducer's rigid rise and its flights, in the same keys for every tier (``statistics.transducer``).

- ``max_rise_m``: largest rise of the transducer's rigid motion above its start;
- ``mean_displacement_m``: mean of that motion above its start;
- flights: intervals in which the transducer touches nothing below it and rises at least
  ``min_flight_rise_m`` (50 µm: flights one could film; the 20 kHz hammering of the tip on the ball
  opens the contact for tens of microseconds with rises of nanometres to micrometres):
  ``flight_count``, ``flight_rate_per_s``, ``flight_duration_mean_s``, ``flight_apex_max_m`` (apex
  above the start), ``min_flight_rise_m``.

The tiers measure the rigid motion differently: the FE and modal tiers average the drive point's
displacement over one drive period (the vibration averages out), the lumped tier has the rigid
coordinate z and the exact take-off velocity of every flight (apex z + z'^2 / 2a). The lumped tier
adds the flight-duration spread and histogram (``flight_durations.png``) and the rise per half run.

Runs of at least ~0.11 s (every tier): ``statistics.interval_95`` holds the half-widths of the 95 %
batch-means intervals of the time-mean statistics (:func:`batch_intervals`); a sweep draws them as error bars.
A sweep of ``transient.loads.fe_force_N`` is plotted against the downforce, -F_z [N] (:meth:`sweep_axis`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app import series as S
from app.intervals import half_width_95
from app.scenes.registry import SceneReport, register
from app.transient.impacts import closed_intervals, period_average


def transient_statistics(data: dict[str, np.ndarray], cfg) -> dict:
    """``{"transducer": ...}`` of an FE/modal run from its time series (empty without the drive
    point's displacement): the rigid motion is the drive point's displacement averaged over a drive
    period; the transducer is in flight while every FE contact (node, surface) is open."""
    t = data.get(S.TIME)
    point = S.point_displacement(cfg.drive.point)
    if t is None or t.shape[0] < 2 or point not in data:
        return {}
    duration = float(t[-1] - t[0])
    fe_closed = np.zeros(t.size, dtype=bool)
    for c in cfg.contacts:
        if c.kind in ("surface", "node"):
            fe_closed |= data[S.contact_closed(c.name)] > 0
    t_mean, z_mean = period_average(t, data[point], 1.0 / cfg.drive.frequency_Hz)
    z_start = z_mean[0]
    flights, apexes = [], []
    for a, b in closed_intervals(~fe_closed) if fe_closed.any() else []:
        if a == 0:
            continue      # open from the start: no take-off
        inside = (t_mean >= t[a]) & (t_mean <= t[b])
        if not inside.any():
            continue
        rise = float(z_mean[inside].max() - np.interp(t[a], t_mean, z_mean))
        if rise >= cfg.min_flight_rise_m:
            flights.append(t[b] - t[a])
            apexes.append(float(z_mean[inside].max() - z_start))
    return {"transducer": {
        "max_rise_m": float(z_mean.max() - z_start),
        "mean_displacement_m": float(np.mean(z_mean - z_start)),
        "flight_count": len(flights),
        "flight_rate_per_s": len(flights) / duration,
        "flight_duration_mean_s": float(np.mean(flights)) if flights else 0.0,
        "flight_apex_max_m": float(np.max(apexes)) if apexes else 0.0,
        "min_flight_rise_m": cfg.min_flight_rise_m,
    }}


#: batch means: the run after its first tenth, cut into this many equal windows
BATCHES = 10
#: windows shorter than this are not long against the impact motion's correlation time (a few ms: the
#: tiers' comparison in BENCHMARKS.md used 100 ms windows), so their means are not independent
MIN_BATCH_S = 0.01
#: the statistics that are means over time (rates, mean force and power), with a batch-means interval
_BATCH_KEYS = ("impact_rate_per_s", "mean_force_N", "mean_power_W")


def batch_intervals(data: dict[str, np.ndarray], cfg) -> dict:
    """Half-widths of the 95 % confidence intervals of the run's time-mean statistics (impact rates per
    contact, a foundation's mean force and power) from batch means: the run after its first tenth (the
    start-up) in ``BATCHES`` equal windows, each statistic computed per window by the run's own code
    (app.transient.impacts.run_statistics), interval = t_{0.975, B-1} s / sqrt(B). The impact motion is
    chaotic, so one run's statistic is a sample: the interval says how far another run may land. Empty when
    the windows would be shorter than ``MIN_BATCH_S``. Keys as in ``statistics`` (e.g.
    ``impact_rate_per_s.stem_rock``), under ``statistics.interval_95``."""
    from app.transient.impacts import run_statistics

    t = data.get(S.TIME)
    if t is None or t.size < 2 * BATCHES:
        return {}
    edges = np.linspace(t[0] + 0.1 * (t[-1] - t[0]), t[-1], BATCHES + 1)
    if edges[1] - edges[0] < MIN_BATCH_S:
        return {}
    samples: dict[tuple, list] = {}
    for lo, hi in zip(edges[:-1], edges[1:]):
        rows = (t > lo) & (t <= hi)
        window = run_statistics({name: array[rows] for name, array in data.items()
                                 if getattr(array, "shape", ())[:1] == t.shape}, cfg)
        for group, values in window.items():
            if not isinstance(values, dict):
                continue
            for key, value in values.items():
                if group in _BATCH_KEYS or key in _BATCH_KEYS:
                    samples.setdefault((group, key), []).append(float(value))
    out: dict = {}
    for (group, key), values in samples.items():
        if len(values) == BATCHES:
            out.setdefault(group, {})[key] = half_width_95(values)
    return out


def lumped_batch_intervals(events: np.ndarray, duration_s: float) -> dict:
    """As :func:`batch_intervals` for the lumped tier, from its exact event table (its samples are too coarse for
    microsecond contacts): per window, the impact rates (closing events) per contact and the rock's mean force
    (the impulses of the stem-rock contacts ending in the window over its width); the same windows and
    t-interval (the method of bench/bench_tier_statistics.py)."""
    from app.lumped import kernel as K
    from app.lumped.parameters import CONTACT_NAMES

    edges = np.linspace(0.1 * duration_s, duration_s, BATCHES + 1)
    if edges[1] - edges[0] < MIN_BATCH_S or events.size == 0:
        return {}
    ev = np.asarray(events)
    closing = ev[:, K.EV_CLOSING] == 1.0
    rates = {name: [] for name in CONTACT_NAMES}
    force = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (ev[:, K.EV_TIME] > lo) & (ev[:, K.EV_TIME] <= hi)
        for c, name in enumerate(CONTACT_NAMES):
            rates[name].append(np.sum(inside & closing & (ev[:, K.EV_CONTACT] == c)) / (hi - lo))
        rock_ends = inside & ~closing & (ev[:, K.EV_CONTACT] == CONTACT_NAMES.index("stem_rock"))
        force.append(float(np.sum(ev[rock_ends, K.EV_IMPULSE])) / (hi - lo))
    return {"impact_rate_per_s": {name: half_width_95(v) for name, v in rates.items()},
            "stem_rock_foundation": {"mean_force_N": half_width_95(force)}}


def lumped_statistics(data: dict[str, np.ndarray], parameters: dict, duration_s: float, min_rise_m: float,
                      bins: int) -> dict:
    """``{"transducer": ...}`` of a lumped run from its time series and event table (app/lumped/outputs.py):
    flights are the tip/free-mass open intervals in which z rises at least ``min_rise_m``. While that contact
    is open the rigid coordinate moves on z'' = -(g + F_a / m_t), so the rise of a flight is
    max(z', 0)^2 / (2 a) at take-off and its apex z + rise (exact, from the events, not sampled)."""
    from app.lumped import kernel as K
    from app.lumped.stats import open_intervals

    accel = parameters["gravity_m_per_s2"] + parameters["downforce_N"] / parameters["transducer_mass_kg"]
    events = np.asarray(data["events"])
    t = data[S.TIME]
    z = np.asarray(data[S.body_position("transducer")]).reshape(t.size, -1)[:, 0]
    z0 = float(z[0])
    initially_closed = bool(np.asarray(data[S.contact_closed("tip_ball")]).reshape(-1)[0] > 0)
    intervals = open_intervals(events, 0, initially_closed, duration_s)
    durations, apexes, starts, censored = [], [], [], 0
    for start, end, row, ends_at_end in intervals:
        if row < 0 or accel <= 0:
            continue  # open from the start: no take-off
        z_takeoff, zd_takeoff = events[row, K.EV_Z], events[row, K.EV_ZDOT]
        rise = max(zd_takeoff, 0.0) ** 2 / (2.0 * accel)
        if rise < min_rise_m:
            continue
        if ends_at_end:
            censored += 1
            continue
        durations.append(end - start)
        apexes.append(z_takeoff + rise - z0)
        starts.append(start)
    durations, apexes, starts = np.asarray(durations), np.asarray(apexes), np.asarray(starts)
    counts, edges = (
        np.histogram(durations, bins=bins) if len(durations) else (np.zeros(bins, int), np.zeros(bins + 1))
    )
    half = 0.5 * duration_s
    apex_max = float(apexes.max()) if len(apexes) else 0.0
    return {"transducer": {
        "max_rise_m": float(max(np.max(z) - z0, apex_max)),
        "max_rise_first_half_m": float(np.max(z[t < half]) - z0),
        "max_rise_second_half_m": float(np.max(z[t >= half]) - z0),
        "mean_displacement_m": float(np.mean(z) - z0),
        "flight_count": int(len(durations)),
        "flight_rate_per_s": len(durations) / duration_s,
        "flight_duration_mean_s": float(durations.mean()) if len(durations) else 0.0,
        "flight_duration_std_s": float(durations.std()) if len(durations) else 0.0,
        "flight_duration_cv": float(durations.std() / durations.mean()) if len(durations) > 1 else 0.0,
        "flight_duration_histogram": {"bin_edges_s": edges.tolist(), "counts": counts.tolist()},
        "flight_apex_mean_m": float(apexes.mean()) if len(apexes) else 0.0,
        "flight_apex_max_m": apex_max,
        "flight_count_first_half": int(np.sum(starts < half)) if len(starts) else 0,
        "flight_count_second_half": int(np.sum(starts >= half)) if len(starts) else 0,
        "flights_still_open_at_end": censored,
        "min_flight_rise_m": min_rise_m,
    }}


def flight_histogram(stats: dict, out_dir: Path, title: str) -> list[str]:
    """``flight_durations.png`` when the statistics hold a flight-duration histogram (lumped tier)."""
    hist = (stats.get("transducer") or {}).get("flight_duration_histogram")
    if not hist or not sum(hist["counts"]):
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    edges = np.asarray(hist["bin_edges_s"]) * 1e3
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.bar(edges[:-1], hist["counts"], width=np.diff(edges), align="edge", edgecolor="k")
    ax.set_xlabel("flight duration [ms]")
    ax.set_ylabel("count")
    ax.set_title(f"{title}: transducer flights" if title else "transducer flights")
    fig.tight_layout()
    fig.savefig(Path(out_dir) / "flight_durations.png", dpi=120)
    plt.close(fig)
    return ["flight_durations.png"]


class PercussionDrill(SceneReport):
    """The drill: the transducer's rise and flights (``statistics.transducer``), its table rows and the
    flight-duration histogram."""

    name = "percussion-drill"
    sweep_columns = ("statistics.transducer.max_rise_m", "statistics.transducer.flight_rate_per_s",
                     "statistics.impact_rate_per_s.stem_rock", "statistics.impact_rate_per_s.tip_ball",
                     "statistics.stem_rock_foundation.mean_force_N", "statistics.stem_rock_foundation.mean_power_W",
                     "statistics.stem_rock_foundation.impulse_per_impact_mean_N_s")

    def check(self, case) -> None:
        from app.errors import CaseError

        if case.tier == "lumped" and case.lumped.model != "impact_chain":
            raise CaseError(case.source, "lumped.model", "the drill's lumped model is 'impact_chain' (transducer, free "
                                                         f"mass, stem, rock), not {case.lumped.model!r}")

    def statistics(self, data: dict, case, results: dict) -> dict:
        if case.tier == "lumped":
            section = case.lumped
            if "events" not in data or S.TIME not in data:
                return {}
            out = lumped_statistics(data, results["parameters"], results["simulated_time_s"],
                                    section.output.min_flight_rise_m, section.output.histogram_bins)
            intervals = lumped_batch_intervals(np.asarray(data["events"]), results["simulated_time_s"])
            if intervals:
                out["interval_95"] = intervals
            return out
        out = transient_statistics(data, case.transient)
        intervals = batch_intervals(data, case.transient)
        if intervals:
            out["interval_95"] = intervals
        return out

    def table_rows(self, results: dict) -> list[tuple[str, str, str]]:
        transducer = (results.get("statistics") or {}).get("transducer")
        if not transducer:
            return []
        return [("transducer: largest rise", f"{transducer['max_rise_m'] * 1e3:.4g}", "mm"),
                ("transducer: flights", f"{transducer['flight_count']}", "1"),
                ("transducer: flight rate", f"{transducer['flight_rate_per_s']:.4g}", "1/s")]

    def sweep_axis(self, key: str):
        """The FE force is a mesh-axis vector; a designer sweeps the downforce: -F along the last axis."""
        if key == "transient.loads.fe_force_N":
            return "downforce [N]", -1, -1.0
        return None

    def outputs(self, results: dict, out_dir: Path, title: str, plots: bool = True) -> list[str]:
        return flight_histogram(results.get("statistics") or {}, out_dir, title) if plots else []


SCENE = register(PercussionDrill())
