"""Motor plots: one operating point (pressure round the ring, the contact point's path) and speed-torque
curves (speed, output power and efficiency against load torque, one curve per preload)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

RING_PLOT = "motor_ring_pressure.png"
PATH_PLOT = "motor_contact_path.png"
CURVE_PLOT = "motor_speed_torque.png"


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}


def operating_point_plots(out_dir: Path, ring_csv: Path, path_csv: Path, title: str = "") -> list[str]:
    ring = _read_csv(ring_csv)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(ring["angle_deg"], ring["mean_pressure_Pa"] * 1e-6, label="mean over the steady window")
    ax.plot(ring["angle_deg"], ring["last_pressure_Pa"] * 1e-6, ".", ms=3, label="at the last step")
    ax.set_xlabel("angle round the ring [deg]")
    ax.set_ylabel("contact pressure [MPa]")
    ax.set_xlim(0, 360)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(f"{title}\ncontact pressure round the ring", fontsize=9)
    fig.tight_layout()
    fig.savefig(out_dir / RING_PLOT, dpi=110)
    plt.close(fig)

    path = _read_csv(path_csv)
    fig, ax = plt.subplots(figsize=(4.5, 4))
    ax.plot(path["tangential_m"] * 1e6, path["normal_m"] * 1e6, "-")
    ax.plot(path["tangential_m"][:1] * 1e6, path["normal_m"][:1] * 1e6, "o", ms=4)
    ax.set_xlabel("circumferential displacement [µm]")
    ax.set_ylabel("normal displacement (towards the rotor: -) [µm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"{title}\npath of a contact node over the last period", fontsize=9)
    fig.tight_layout()
    fig.savefig(out_dir / PATH_PLOT, dpi=110)
    plt.close(fig)
    return [RING_PLOT, PATH_PLOT]


def speed_torque_plot(out_path: Path, curves: dict[str, dict[str, np.ndarray]], title: str = "") -> None:
    """``curves``: label -> {"torque_N_m", "speed_rpm", "output_power_W", "efficiency"} arrays."""
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8))
    for label, c in curves.items():
        order = np.argsort(c["torque_N_m"])
        torque = np.asarray(c["torque_N_m"])[order] * 1e3
        axes[0].plot(torque, np.asarray(c["speed_rpm"])[order], "o-", ms=4, label=label)
        axes[1].plot(torque, np.asarray(c["output_power_W"])[order] * 1e3, "o-", ms=4, label=label)
        axes[2].plot(torque, 100 * np.asarray(c["efficiency"])[order], "o-", ms=4, label=label)
    for ax, ylabel in zip(axes, ("speed [rpm]", "output power [mW]", "efficiency [%]")):
        ax.set_xlabel("load torque [mN m]")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out_path, dpi=110)
    plt.close(fig)
