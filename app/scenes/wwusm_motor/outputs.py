"""The motor's CSVs and plots of one operating point (from the time series of any tier): the pressure round the
ring and the contact states along it (``motor_ring.csv``), the contact in the wave's frame: pressure, contact,
stick and slip against the wave's phase per ring across the band (``motor_wave_frame.csv``), the contact point's
path over the last period (``motor_contact_path.csv``), and the rotor's speed against time with the steady window
marked."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from app import series as S
from app.files import replace_file

RING_CSV = "motor_ring.csv"
PATH_CSV = "motor_contact_path.csv"
RING_PLOT = "motor_ring_pressure.png"
PATH_PLOT = "motor_contact_path.png"
SPEED_PLOT = "motor_speed.png"
WAVE_CSV = "motor_wave_frame.csv"
WAVE_PLOT = "motor_wave_frame.png"


def write_csv(path: Path, rows: dict) -> None:
    """Columns of equal length as CSV, a header of their names (whole or not at all: a killed run)."""
    keys = list(rows)
    lines = [",".join(keys)]
    for i in range(len(rows[keys[0]])):
        lines.append(",".join(f"{rows[k][i]:.8g}" for k in keys))
    replace_file(path, ("\n".join(lines) + "\n").encode())


def write_outputs(results: dict, out_dir: Path, title: str, plots: bool) -> list[str]:
    from app.series import read_time_series

    point = (results.get("statistics") or {}).get("motor")
    if not point or not results.get("time_series"):
        return []
    data = read_time_series(out_dir / results["time_series"])
    names = [k[: -len("_sites_geometry")] for k in data if k.endswith("_sites_geometry")]
    written = []
    window = point["window_s"]
    t = data[S.TIME]
    start = t[-1] - window
    if names:
        contact = names[0]
        geometry = data[S.sites_table(contact, "geometry")]
        times = data[S.sites_table(contact, "time")]
        rows = (times[:, 0] >= start * (1 - 1e-9))
        if not rows.any():
            rows[-1] = True
        angle = np.degrees(np.arctan2(geometry[:, 1], geometry[:, 0])) % 360.0
        # rings across the band (sample_rings > 1) share their angles: one row per angle, the area-weighted mean
        # across the band's height
        angles, column = np.unique(np.round(angle, 9), return_inverse=True)
        area = geometry[:, 3]
        per_angle = np.bincount(column, weights=area, minlength=angles.size)

        def across(values):
            return np.bincount(column, weights=values * area, minlength=angles.size) / per_angle

        pressure = data[S.sites_table(contact, "pressure")]
        ring = {"angle_deg": angles,
                "mean_pressure_Pa": across(pressure[rows].mean(axis=0)),
                "last_period_pressure_Pa": across(pressure[-1]),
                "contact_fraction": across(data[S.sites_table(contact, "closed")][rows].mean(axis=0)),
                "stick_fraction": across(data[S.sites_table(contact, "stick")][rows].mean(axis=0))}
        write_csv(out_dir / RING_CSV, ring)
        written.append(RING_CSV)
        frame = wave_frame(data, contact, rows, point.get("forward_slip_direction_e1", 1.0))
        if frame is not None:
            write_csv(out_dir / WAVE_CSV, frame)
            written.append(WAVE_CSV)
            if plots:
                written += _wave_plot(out_dir, frame, title)
        probe = S.contact_probe(contact)
        if probe in data:
            period = point["window_s"] / max(point["window_periods"], 1)
            last = t > t[-1] - period * (1 + 1e-9)
            path = data[probe][last]
            write_csv(out_dir / PATH_CSV, {"time_s": t[last], "normal_m": path[:, 0], "tangential_m": path[:, 1],
                                           "meridional_m": path[:, 2]})
            written.append(PATH_CSV)
        if plots:
            written += _plots(out_dir, ring, data, probe, t, start, title)
    return written


def wave_frame(data: dict, contact: str, rows: np.ndarray, forward: float) -> dict | None:
    """The contact in the wave's frame over the window's rows (the ``wave_frame`` table, app/contact/tables.py):
    per ring across the band (``ring`` 0: the one nearest the band's middle; its height ``ring_height_m``) and per
    bin of wave phase (``wave_phase_deg``, the bin's centre, 0 the crest, positive ahead of it in the direction
    the wave travels, -180 to 180), the mean pressure, the fractions of the time the ring's sites at that phase
    are in contact, sticking, slipping forward (``forward``: the sign of e1 that is forward) or backward, the
    slip speed's circumferential and meridional parts while slipping, and the bin's share of the mean normal force
    (its sum over bins and rings: the contact's mean normal force). None for a series without the table."""
    name = S.sites_table(contact, "wave_frame")
    if name not in data:
        return None
    table = data[name]
    # the rows with the sites' wave phases known (not a run's first interval)
    rows = rows & (table[..., 0].reshape(len(table), -1).sum(axis=1) > 0)
    if not rows.any():
        return None
    bins = table[rows].sum(axis=0)                         # (rings, bins, columns), each row a mean over its interval
    n_rows = int(rows.sum())
    n_rings, n_bins = bins.shape[:2]
    heights = data[S.sites_table(contact, "geometry")][:, 2].reshape(n_rings, -1).mean(axis=1)
    centre = 360.0 * np.arange(n_bins) / n_bins
    phase = np.where(centre > 180.0, centre - 360.0, centre)
    order = np.argsort(phase)
    area, force, closed, stick, positive, negative, along_e1, along_e2 = np.moveaxis(bins[:, order], -1, 0)
    slipping = positive + negative

    def ratio(a, b):
        return np.divide(a, b, out=np.zeros_like(a), where=b > 0)

    forward_area, backward_area = (positive, negative) if forward > 0 else (negative, positive)
    return {"ring": np.repeat(np.arange(n_rings), n_bins).astype(float),
            "ring_height_m": np.repeat(heights, n_bins),
            "wave_phase_deg": np.tile(phase[order], n_rings),
            "mean_pressure_Pa": ratio(force, area).ravel(),
            "contact_fraction": ratio(closed, area).ravel(),
            "stick_fraction": ratio(stick, area).ravel(),
            "forward_slip_fraction": ratio(forward_area, area).ravel(),
            "backward_slip_fraction": ratio(backward_area, area).ravel(),
            "slip_speed_circumferential_m_per_s": ratio(along_e1, slipping).ravel(),
            "slip_speed_meridional_m_per_s": ratio(along_e2, slipping).ravel(),
            "normal_force_N": (force / n_rows).ravel()}


def _wave_plot(out_dir, frame, title) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for ring in np.unique(frame["ring"]):
        mine = frame["ring"] == ring
        label = f"ring {int(ring)} (z = {frame['ring_height_m'][mine][0] * 1e3:.4g} mm)"
        line, = top.plot(frame["wave_phase_deg"][mine], frame["mean_pressure_Pa"][mine] * 1e-6, "o-", ms=3,
                         label=label)
        bottom.plot(frame["wave_phase_deg"][mine], frame["stick_fraction"][mine], "-", color=line.get_color(),
                    label=f"stick, ring {int(ring)}")
        bottom.plot(frame["wave_phase_deg"][mine], frame["forward_slip_fraction"][mine], "--",
                    color=line.get_color(), label=f"forward slip, ring {int(ring)}")
        bottom.plot(frame["wave_phase_deg"][mine], frame["backward_slip_fraction"][mine], ":",
                    color=line.get_color(), label=f"backward slip, ring {int(ring)}")
    top.axvline(0.0, color="0.6", lw=0.8)
    bottom.axvline(0.0, color="0.6", lw=0.8)
    top.set_ylabel("mean contact pressure [MPa]")
    bottom.set_ylabel("fraction of the time")
    bottom.set_xlabel("wave phase from the crest [deg] (+: ahead, in the direction the wave travels)")
    bottom.set_xlim(-180, 180)
    top.legend(loc="best", fontsize=7)
    bottom.legend(loc="best", fontsize=6, ncol=2)
    top.set_title(f"{title}\nthe contact in the wave's frame (steady window)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out_dir / WAVE_PLOT, dpi=110)
    plt.close(fig)
    return [WAVE_PLOT]


def _plots(out_dir, ring, data, probe, t, start, title) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(ring["angle_deg"], ring["mean_pressure_Pa"] * 1e-6, label="mean over the steady window")
    ax.plot(ring["angle_deg"], ring["last_period_pressure_Pa"] * 1e-6, ".", ms=3, label="mean over the last period")
    ax.set_xlabel("angle round the ring [deg]")
    ax.set_ylabel("contact pressure [MPa]")
    ax.set_xlim(0, 360)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{title}\ncontact pressure round the ring", fontsize=9)
    fig.tight_layout()
    fig.savefig(out_dir / RING_PLOT, dpi=110)
    plt.close(fig)
    written.append(RING_PLOT)
    if probe in data:
        path = data[probe][t > t[-1] - (t[-1] - start) / max(1, ring.get("periods", 1))]
        fig, ax = plt.subplots(figsize=(4.5, 4))
        ax.plot(path[:, 1] * 1e6, path[:, 0] * 1e6, "-")
        ax.plot(path[:1, 1] * 1e6, path[:1, 0] * 1e6, "o", ms=4)
        ax.set_xlabel("circumferential displacement [µm]")
        ax.set_ylabel("normal displacement [µm]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{title}\npath of a contact point", fontsize=9)
        fig.tight_layout()
        fig.savefig(out_dir / PATH_PLOT, dpi=110)
        plt.close(fig)
        written.append(PATH_PLOT)
    speed_key = next((k for k in data if k.endswith("_angular_velocity_rad_per_s")), None)
    if speed_key is not None:
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.plot(t * 1e3, data[speed_key][:, 0] * 60 / (2 * math.pi), lw=0.6)
        ax.axvspan(start * 1e3, t[-1] * 1e3, color="0.85", label="steady window")
        ax.set_xlabel("time [ms]")
        ax.set_ylabel("rotor speed [rpm]")
        ax.legend(loc="best", fontsize=8)
        ax.set_title(f"{title}\nrotor speed against time", fontsize=9)
        fig.tight_layout()
        fig.savefig(out_dir / SPEED_PLOT, dpi=110)
        plt.close(fig)
        written.append(SPEED_PLOT)
    return written


CURVE_CSV = "motor_speed_torque.csv"
CURVE_PLOT = "motor_speed_torque.png"
#: columns of the speed-torque CSV (keys of an operating point; ``branch`` first)
CURVE_COLUMNS = ("load_torque_N_m", "speed_rpm", "speed_rad_per_s", "output_power_W", "electrical_power_W",
                 "efficiency", "friction_loss_W", "damping_loss_W", "wave_amplitude_m", "contact_half_angle_rad",
                 "speed_over_surface_speed")


def write_curves(results: dict, out_dir: Path, title: str, plots: bool) -> list[str]:
    """The speed-torque curves of a steady solve (``results["curves"]``: branch -> operating points, no load to
    stall) as ``motor_speed_torque.csv`` (column ``branch``: 0 upper, 1 lower) and its plot."""
    curves = results["curves"]
    table = {"branch": [], **{k: [] for k in CURVE_COLUMNS}}
    for index, points in enumerate(curves.values()):
        for point in points:
            table["branch"].append(float(index))
            for key in CURVE_COLUMNS:
                table[key].append(float(point[key]))
    if not table["branch"]:
        return []
    write_csv(out_dir / CURVE_CSV, table)
    written = [CURVE_CSV]
    if plots:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for (name, points), style in zip(curves.items(), ("o-", "s--")):
            if points:
                ax.plot([p["load_torque_N_m"] * 1e3 for p in points], [p["speed_rpm"] for p in points], style, ms=4,
                        label=f"{name} branch")
        ax.set_xlabel("load torque [mN m]")
        ax.set_ylabel("rotor speed [rpm]")
        ax.legend(loc="best", fontsize=8)
        ax.set_title(f"{title}\nspeed-torque (lumped: wave mode + friction-drive law)", fontsize=9)
        fig.tight_layout()
        fig.savefig(out_dir / CURVE_PLOT, dpi=110)
        plt.close(fig)
        written.append(CURVE_PLOT)
    return written
