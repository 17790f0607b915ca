"""PNG plots (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Unit suffixes of piezodyn's names (summary.json keys, case keys) -> (shown unit, factor from SI).
# Lengths in mm, frequencies in kHz, masses in g, times in ms, as the terminal summaries show them.
UNIT_SUFFIXES = (
    ("_m_per_s", "mm/s", 1e3),
    ("_N_s_per_m", "N s/m", 1.0),
    ("_N_per_m", "N/mm", 1e-3),
    ("_N_per_V", "N/V", 1.0),
    ("_m_per_V", "µm/V", 1e6),
    ("_m_per_s2", "m/s²", 1.0),
    ("_per_s", "1/s", 1.0),
    ("_N_s", "N s", 1.0),
    ("_Hz", "kHz", 1e-3),
    ("_kg", "g", 1e3),
    ("_deg", "deg", 1.0),
    ("_m", "mm", 1e3),
    ("_s", "ms", 1e3),
    ("_W", "W", 1.0),
    ("_N", "N", 1.0),
    ("_J", "J", 1.0),
    ("_V", "V", 1.0),
    ("_S", "S", 1.0),
    ("_F", "nF", 1e9),
)
# Path segments that only group keys; left out of labels.
_GROUPS = {"lumped", "transient", "statistics", "geometry", "parameters", "results"}


def quantity_label(name: str) -> tuple[str, float]:
    """A dotted piezodyn name -> (axis label with unit, factor to multiply SI values by):
    ``transient.statistics.transducer.max_rise_m`` -> ("transducer max rise [mm]", 1e3)."""
    words, unit, scale = [], None, 1.0
    for segment in name.split("."):
        if segment in _GROUPS:
            continue
        for suffix, shown, factor in UNIT_SUFFIXES:
            if segment.endswith(suffix) and len(segment) > len(suffix):
                segment = segment[: -len(suffix)]
                unit, scale = shown, factor
                break
        words.append(segment.replace("_", " "))
    text = " ".join(words).replace("k eff", "k_eff").replace("fe force", "FE force") or name
    return (f"{text} [{unit}]" if unit else text), scale


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
