"""PNG plots (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def admittance_plot(path: Path, harmonic: dict, f_r: float | None, f_a: float | None, circuit: dict | None = None):
    f = np.array(harmonic["frequency_Hz"])
    mag = np.array(harmonic["admittance_magnitude_S"])
    phase = np.array(harmonic["admittance_phase_deg"])
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    ax1.semilogy(f / 1e3, mag, "o-", ms=3, label="FE")
    ax2.plot(f / 1e3, phase, "o-", ms=3, label="FE")
    if circuit and "clamped_capacitance_F" in circuit:
        from app.circuit import bvd_admittance

        fine = np.linspace(f[0], f[-1], 2000)
        y = bvd_admittance(circuit, fine)
        ax1.semilogy(fine / 1e3, np.abs(y), "-", lw=1, label="1-DOF equivalent circuit")
        ax2.plot(fine / 1e3, np.degrees(np.angle(y)), "-", lw=1, label="1-DOF equivalent circuit")
    for ax in (ax1, ax2):
        for value in (f_r, f_a):
            if value:
                ax.axvline(value / 1e3, color="gray", ls="--", lw=0.8)
        ax.grid(True, which="both", alpha=0.3)
    ax1.set_ylabel("|Y| [S]")
    ax2.set_ylabel("phase(Y) [deg]")
    ax2.set_xlabel("frequency [kHz]")
    ax1.legend()
    ax1.set_title("Electrical admittance (dashed: modal f_r, f_a)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
