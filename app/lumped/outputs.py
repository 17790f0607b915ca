"""The lumped tier's time series under the output convention of every tier (app/series.py): the
drill scene's bodies and contacts under the FE case's names (``ball``, ``stem``; ``tip_ball``,
``ball_stem``, ``stem_rock``), one vertical axis, upward positive; and its event table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app import series as S
from app.lumped.model import ID3, IV, IVD, IW, IWD, IX, IZ, IZD
from app.lumped.parameters import CONTACT_NAMES

EVENTS = "events"
EVENT_COLUMNS = (
    "time_s",
    "contact_index",
    "closing",
    "relative_velocity_m_per_s",
    "transducer_z_m",
    "transducer_velocity_m_per_s",
    "impulse_of_closed_interval_N_s",
    "layer_loss_so_far_J",
)
EVENT_UNITS = "s,-,-,m/s,m,m/s,N s,J"
# The drill's rigid bodies as the lumped coordinates hold them (FE case names), and the body each
# contact's force acts on in the convention (the rigid body of the tip's node contact, the upper
# body of a link): +1 if that force points up for a compressed contact.
POINT = "tip"
BODIES = {"transducer": (IZ, IZD, "rigid transducer coordinate z"), "ball": (IW, IWD, "free mass coordinate w"),
          "stem": (IV, IVD, "stem coordinate v")}
PLOTTED_BODIES = ("ball", "stem")
FORCE_SIGN = {"tip_ball": -1.0, "ball_stem": 1.0, "stem_rock": 1.0}
FILE_ATTRS = {"model": "piezodyn lumped drill model (eqs. 5-16)",
              "coordinates": "upward positive; zero when the parts rest on each other unloaded"}


def contact_forces_N(samples_y: np.ndarray, samples_mode: np.ndarray, force_rows: np.ndarray) -> np.ndarray:
    """(n, 3): forces of the closed layers at the samples (0 when open).

    One matrix product per block of rows, as the series has always been written; a block of one row is
    padded to two, because BLAS takes a single row through its matrix-vector kernel, whose summation
    order differs in the last bit from the matrix-matrix kernel's (so a run resumed at any row writes
    the same bits as the run in one go)."""
    y = np.ascontiguousarray(samples_y, dtype=np.float64)
    single = y.shape[0] == 1
    if single:
        y = np.concatenate([y, y])
    forces = y @ force_rows.T
    if single:
        forces = forces[:1]
    closed = (np.asarray(samples_mode)[:, None] >> np.arange(3)[None, :]) & 1
    return forces * closed


def columns() -> dict[str, tuple[str, str]]:
    """Every time-series column: name -> (unit, what it is)."""
    out = {S.TIME: ("s", "sample time"), S.STEP: ("s", "time since the previous sample"),
           S.point_displacement(POINT): ("m", "transducer tip x + z"),
           "vibration_displacement_m": ("m", "modal coordinate x")}
    for body, (_, _, doc) in BODIES.items():
        units = S.body_columns(body)
        out[S.body_position(body)] = (units[S.body_position(body)], f"{doc} (0: the parts rest on each other unloaded)")
        out[S.body_velocity(body)] = (units[S.body_velocity(body)], f"rate of the {doc}")
    out["rock_surface_displacement_m"] = ("m", "rock surface s = -d3")
    for name in CONTACT_NAMES:
        units = S.contact_columns(name)
        out[S.contact_force(name)] = (units[S.contact_force(name)],
                                      f"Kelvin-Voigt force of contact {name} on its rigid / upper body")
        out[S.contact_closed(name)] = (units[S.contact_closed(name)], f"1 while contact {name} is closed")
    return out


def series_rows(t: np.ndarray, y: np.ndarray, mode: np.ndarray, force_rows: np.ndarray,
                t_previous_s: float) -> dict[str, np.ndarray]:
    """The time-series rows of samples (times ``t`` [s], states ``y``, contact modes ``mode``);
    ``t_previous_s``: the time of the sample before the first (its own time for the first sample)."""
    forces = contact_forces_N(y, mode, force_rows)
    rows = {S.TIME: t, S.STEP: np.diff(t, prepend=t_previous_s), S.point_displacement(POINT): y[:, IX] + y[:, IZ],
            "vibration_displacement_m": y[:, IX]}
    for body, (i, i_dot, _) in BODIES.items():
        rows[S.body_position(body)] = y[:, i:i + 1]
        rows[S.body_velocity(body)] = y[:, i_dot:i_dot + 1]
    rows["rock_surface_displacement_m"] = -y[:, ID3]
    for j, name in enumerate(CONTACT_NAMES):
        rows[S.contact_force(name)] = FORCE_SIGN[name] * forces[:, j:j + 1]
        rows[S.contact_closed(name)] = (mode >> j) & 1
    return {name: np.asarray(value, dtype=np.float64) for name, value in rows.items()}


def describe_series(path: Path) -> None:
    """Attributes the run loop's writer does not set (rank 0, after the run): what each column is, the
    file's model and coordinate convention, the event table's column names and contact indices."""
    import h5py

    with h5py.File(path, "a") as f:
        for key, value in FILE_ATTRS.items():
            f.attrs[key] = value
        for name, (_, doc) in columns().items():
            if name in f:
                f[name].attrs[S.DESCRIPTION] = doc
        if EVENTS in f:
            f[EVENTS].attrs["columns"] = ",".join(EVENT_COLUMNS)
            f[EVENTS].attrs["contact_index"] = ",".join(f"{i}={n}" for i, n in enumerate(CONTACT_NAMES))


def plot_spec(downforce_N: float, name: str) -> dict:
    """What the lumped tier's time-series plots show (``results["plot"]``, as the FE tier's):
    titled by the case ``name`` and the downforce."""
    return {"point": POINT, "bodies": list(PLOTTED_BODIES), "contacts": list(CONTACT_NAMES),
            "title": f"{name}, downforce {downforce_N:.3g} N"}
