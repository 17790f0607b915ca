"""HDF5 time series and PNG plots (drill paper Fig. 12: displacements; Fig. 5: force on the rock)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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


def write_time_series(result: SimulationResult, path: Path) -> None:
    import h5py

    y = result.samples_y
    forces = result.contact_forces_N()
    series = {
        "time_s": (result.samples_t_s, "s", "sample time"),
        "tip_displacement_m": (y[:, IX] + y[:, IZ], "m", "transducer tip x + z"),
        "transducer_rigid_displacement_m": (y[:, IZ], "m", "rigid transducer coordinate z"),
        "vibration_displacement_m": (y[:, IX], "m", "modal coordinate x"),
        "free_mass_displacement_m": (y[:, IW], "m", "free mass coordinate w"),
        "stem_displacement_m": (y[:, IV], "m", "stem coordinate v"),
        "rock_surface_displacement_m": (-y[:, ID3], "m", "rock surface s = -d3"),
        "transducer_velocity_m_per_s": (y[:, IZD], "m/s", "z'"),
        "free_mass_velocity_m_per_s": (y[:, IWD], "m/s", "w'"),
        "stem_velocity_m_per_s": (y[:, IVD], "m/s", "v'"),
        "rock_force_N": (forces[:, 2], "N", "force of the rock on the stem (F_c3)"),
    }
    for i, name in enumerate(CONTACT_NAMES):
        series[f"contact_force_{name}_N"] = (forces[:, i], "N", f"Kelvin-Voigt force of contact {name}")
    with h5py.File(path, "w") as f:
        f.attrs["model"] = "piezodyn lumped drill model (eqs. 5-16)"
        f.attrs["coordinates"] = "upward positive; zero when the parts rest on each other unloaded"
        for name, (data, unit, doc) in series.items():
            dset = f.create_dataset(name, data=np.asarray(data, dtype=np.float64), compression="gzip")
            dset.attrs["units"] = unit
            dset.attrs["description"] = doc
        ev = f.create_dataset("events", data=result.events, compression="gzip")
        ev.attrs["columns"] = ",".join(EVENT_COLUMNS)
        ev.attrs["units"] = "s,-,-,m/s,m,m/s,N s,J"
        ev.attrs["contact_index"] = ",".join(f"{i}={n}" for i, n in enumerate(CONTACT_NAMES))


def write_plots(result: SimulationResult, out_dir: Path, title: str, stats: dict | None = None) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_ms = result.samples_t_s * 1e3
    y = result.samples_y
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.plot(t_ms, (y[:, IX] + y[:, IZ]) * 1e3, ":", color="k", lw=0.8, label="transducer tip (x + z)")
    ax.plot(t_ms, y[:, IW] * 1e3, "-", color="tab:blue", lw=0.8, label="free mass (w)")
    ax.plot(t_ms, y[:, IV] * 1e3, "--", color="tab:red", lw=0.8, label="drill stem (v)")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("displacement [mm]")
    ax.set_title(f"{title}: displacements (cf. drill paper Fig. 12)")
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "displacements.png", dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t_ms, result.contact_forces_N()[:, 2], lw=0.6, color="tab:green")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("force on rock [N]")
    ax.set_title(f"{title}: stem/rock contact force at the samples (cf. Fig. 5)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "rock_force.png", dpi=120)
    plt.close(fig)

    files = ["displacements.png", "rock_force.png"]
    hist = (stats or {}).get("transducer", {}).get("flight_duration_histogram")
    if hist and sum(hist["counts"]):
        edges = np.asarray(hist["bin_edges_s"]) * 1e3
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.bar(edges[:-1], hist["counts"], width=np.diff(edges), align="edge", edgecolor="k")
        ax.set_xlabel("flight duration (ms)")
        ax.set_ylabel("count")
        ax.set_title(f"{title}: transducer flight periods")
        fig.tight_layout()
        fig.savefig(out_dir / "flight_durations.png", dpi=120)
        plt.close(fig)
        files.append("flight_durations.png")
    return files
