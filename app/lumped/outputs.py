"""The lumped tier's time series under the output convention of every tier (app/series.py): the
drill scene's bodies and contacts under the FE case's names (``ball``, ``stem``; ``tip_ball``,
``ball_stem``, ``stem_rock``), one vertical axis, upward positive."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app import series as S
from app.lumped.model import ID3, IV, IVD, IW, IWD, IX, IZ, IZD
from app.lumped.parameters import CONTACT_NAMES
from app.lumped.simulate import SimulationResult

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
# The drill's rigid bodies as the lumped coordinates hold them (FE case names), and the body each
# contact's force acts on in the convention (the rigid body of the tip's node contact, the upper
# body of a link): +1 if that force points up for a compressed contact.
POINT = "tip"
BODIES = {"transducer": (IZ, IZD, "rigid transducer coordinate z"), "ball": (IW, IWD, "free mass coordinate w"),
          "stem": (IV, IVD, "stem coordinate v")}
PLOTTED_BODIES = ("ball", "stem")
FORCE_SIGN = {"tip_ball": -1.0, "ball_stem": 1.0, "stem_rock": 1.0}


def write_time_series(result: SimulationResult, path: Path) -> None:
    y, t = result.samples_y, result.samples_t_s
    forces = result.contact_forces_N()
    columns = {S.TIME: (t, "s", "sample time"),
               S.STEP: (np.diff(t, prepend=t[0]), "s", "time since the previous sample"),
               S.point_displacement(POINT): (y[:, IX] + y[:, IZ], "m", "transducer tip x + z"),
               "vibration_displacement_m": (y[:, IX], "m", "modal coordinate x")}
    for body, (i, i_dot, doc) in BODIES.items():
        units = S.body_columns(body)
        columns[S.body_position(body)] = (y[:, i:i + 1], units[S.body_position(body)],
                                          f"{doc} (0: the parts rest on each other unloaded)")
        columns[S.body_velocity(body)] = (y[:, i_dot:i_dot + 1], units[S.body_velocity(body)], f"rate of the {doc}")
    columns["rock_surface_displacement_m"] = (-y[:, ID3], "m", "rock surface s = -d3")
    for j, name in enumerate(CONTACT_NAMES):
        units = S.contact_columns(name)
        columns[S.contact_force(name)] = (FORCE_SIGN[name] * forces[:, j:j + 1], units[S.contact_force(name)],
                                          f"Kelvin-Voigt force of contact {name} on its rigid / upper body")
        columns[S.contact_closed(name)] = ((result.samples_mode >> j) & 1, units[S.contact_closed(name)],
                                           f"1 while contact {name} is closed")
    writer = S.TimeSeriesWriter(path, {k: v[1] for k, v in columns.items()},
                                descriptions={k: v[2] for k, v in columns.items()},
                                attrs={"model": "piezodyn lumped drill model (eqs. 5-16)",
                                       "coordinates": "upward positive; zero when the parts rest on each other "
                                                      "unloaded"})
    writer.write_block({k: np.asarray(v[0], dtype=np.float64) for k, v in columns.items()})
    writer.add_table("events", result.events, "s,-,-,m/s,m,m/s,N s,J", columns=",".join(EVENT_COLUMNS),
                     contact_index=",".join(f"{i}={n}" for i, n in enumerate(CONTACT_NAMES)))
    writer.close()


def plot_spec(downforce_N: float, name: str) -> dict:
    """What the lumped tier's time-series plots show (``results["plot"]``, as the FE tier's):
    titled by the case ``name`` and the downforce."""
    return {"point": POINT, "bodies": list(PLOTTED_BODIES), "contacts": list(CONTACT_NAMES),
            "title": f"{name}, downforce {downforce_N:.3g} N"}
