"""Amplitude and phase of the motor's wave against its drive, over a run's last periods (issue 24: is a wedged
rotor's small wave a detuning from the loaded resonance?).

For each run directory (a motor run's ``transient.h5`` and ``summary.json``): the drive frequency the run used
(``results.transient.drive``: the locked frequency, else the case's), and over the last ``--periods`` drive periods
a least-squares fit of phase A's voltage and of each component of the contact probe's displacement to
cos/sin at that frequency (plus a constant): each component's amplitude, its lag behind the voltage [deg] and its
mean. A shift of the loaded resonance against the drive moves the lag; the same lag on several meshes says the
wave's size is not set by detuning.

    .venv/bin/python bench/motor_drive_phase.py RUN_DIR [RUN_DIR ...] [--periods 20]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import h5py
import numpy as np


def drive_frequency_Hz(run: Path) -> float:
    transient = json.loads((run / "summary.json").read_text())["results"]["transient"]
    drive = transient.get("drive") or {}
    for key in ("frequency_Hz", "locked_frequency_Hz", "drive_frequency_Hz"):
        if key in drive:
            return float(drive[key])
    raise KeyError(f"{run}: no drive frequency in results.transient.drive ({sorted(drive)})")


def fit(t: np.ndarray, y: np.ndarray, frequency_Hz: float) -> tuple[complex, float]:
    """y ~ Re(z e^{i w t}) + c: (z, c)."""
    w = 2 * np.pi * frequency_Hz
    basis = np.c_[np.cos(w * t), np.sin(w * t), np.ones_like(t)]
    a, b, c = np.linalg.lstsq(basis, y, rcond=None)[0]
    return complex(a, -b), float(c)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--periods", type=int, default=20)
    args = parser.parse_args()
    print("| run | drive [Hz] | component | amplitude [µm] | lag behind V_A [deg] | mean [µm] |")
    print("|---|---|---|---|---|---|")
    for run in args.runs:
        frequency = drive_frequency_Hz(run)
        with h5py.File(run / "transient.h5", "r") as f:
            t = f["time_s"][()]
            voltage = f["A_voltage_V"][()]
            probe = next(f[name][()] for name in f if name.endswith("_probe_displacement_m"))
        last = t > t[-1] - args.periods / frequency
        z_v, _ = fit(t[last], voltage[last], frequency)
        for k, name in enumerate("xyz"):
            z, mean = fit(t[last], probe[last, k], frequency)
            lag = np.degrees(np.angle(z_v) - np.angle(z)) % 360
            print(f"| {run.name} | {frequency:.2f} | {name} | {abs(z) * 1e6:.3f} | {lag:.1f} | {mean * 1e6:.3f} |")


if __name__ == "__main__":
    main()
