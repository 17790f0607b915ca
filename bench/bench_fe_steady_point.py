"""One steady operating point of the wedge-wave motor in the FE tier, and the modal tier at the same point.

The point (issue 26): the pinned stator and mesh (``bench/cases/wwusm-motor-pinned.toml``, 130 168 DOFs in the FE
tier), preload 0.98 N, a free rotor under a load torque of 12.929 mN m (half the modal tier's stall torque at 0.98 N,
a point of its speed-torque curve, BENCHMARKS.md), started from the stator's harmonic steady state with the rotor
seated on the highest crest, run until the case's steady-state rule holds (``[transient.steady_state]``: the
cycle-mean speed within 0.5 % over 20 periods). A loaded free rotor rather than the held one: from the harmonic
start a held rotor stays on the bouncing branch in the modal tier (docs/motor-studies.md, "Two regimes"), and a held
rotor's torque ripples by more than 0.5 %, so its run would end at ``end_time_s`` without a steady state.

    # the FE tier (hours; resumes from DIR/checkpoint when it exists, same command again after a kill)
    nice .venv/bin/python bench/bench_fe_steady_point.py fe --out /work/runs/fe_steady
    # the modal tier at the same point (any piezodyn; the comparison reads its transient.h5)
    piezodyn run bench/cases/wwusm-motor-pinned.toml --out MODAL \
        --set 'transient.bodies[0].rotations[0].torque_N_m=-0.012929'
    # the comparison: cycle means over each run's last window (20 periods), speed, torque, N and the stator's
    # loaded wave at the contact point; several modal runs (one setting each: BENCHMARKS.md, "What the gap is made
    # of") against the one FE point
    .venv/bin/python bench/bench_fe_steady_point.py compare --fe /work/runs/fe_steady --modal MODAL [MODAL2 ...]

``fe`` passes ``--set`` keys after ``--set`` to both the run and its resume (the case digest must match).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASE = ROOT / "bench" / "cases" / "wwusm-motor-pinned.toml"
LOAD_N_M = 0.012929
POINT = [f"transient.bodies[0].rotations[0].torque_N_m={-LOAD_N_M!r}"]
FE = ['tier="fe"', "output.fields=false", "output.plots=false", "transient.checkpoint_interval_steps=200"]
WINDOW = 20     # periods: the steady-state rule's window


def run_fe(out: Path, sets: list[str]) -> dict:
    from app.runner import run_case

    resume = (out / "checkpoint").is_dir()
    return run_case(CASE, POINT + FE + sets, out, resume=resume)


def cycle_means(path: Path, frequency_Hz: float) -> dict[str, np.ndarray]:
    """Per drive period [kT, (k+1)T): mean speed [rad/s], friction torque on the rotor [N m] and normal
    force [N] (step-weighted means of each period's rows; the last, partial period left out)."""
    with h5py.File(path, "r") as f:
        t = f["time_s"][()]
        dt = f["dt_s"][()]
        series = {"speed_rad_per_s": f["rotor_angular_velocity_rad_per_s"][()].reshape(len(t), -1)[:, 0],
                  "torque_N_m": f["stator_rotor_torque_N_m"][()].reshape(len(t), -1)[:, 0],
                  "normal_force_N": f["stator_rotor_normal_force_N"][()].reshape(-1)}
        probe = f["stator_rotor_probe_displacement_m"][()].reshape(len(t), -1)[:, 0]
    period = np.floor((t - 0.5 * dt) * frequency_Hz + 1e-9).astype(int)
    closed = np.arange(period.max())            # the last period may be partial
    out = {"period": closed}
    for key, values in series.items():
        out[key] = np.array([np.average(values[period == k], weights=dt[period == k]) for k in closed])
    # the stator's wave under load at the contact point: half the peak-to-peak of the probe's normal displacement
    out["wave_m"] = np.array([0.5 * np.ptp(probe[period == k]) for k in closed])
    return out


def window_powers(path: Path, frequency_Hz: float, window: int, load_N_m: float = LOAD_N_M) -> dict[str, float]:
    """Mean powers [W] over the last ``window`` periods: the electrical input (sum over the electrodes of the
    integral of V dQ), the stator's damping and the contact's friction (rates of their dissipated energies) and the
    output (load torque x speed)."""
    with h5py.File(path, "r") as f:
        t = f["time_s"][()]
        first = int(np.searchsorted(t, t[-1] - window / frequency_Hz * (1 - 1e-9)))
        span = t[-1] - t[first]
        electrodes = [k[: -len("_voltage_V")] for k in f if k.endswith("_voltage_V") and k != "drive_voltage_V"]
        electrical = 0.0
        for name in electrodes:
            voltage, charge = f[f"{name}_voltage_V"][first:], f[f"{name}_charge_C"][first:]
            electrical += float(np.sum(0.5 * (voltage[1:] + voltage[:-1]) * np.diff(charge)))

        def rate(key):
            return float(f[key][-1] - f[key][first]) / span

        speed = f["rotor_angular_velocity_rad_per_s"][first:].reshape(-1)
        return {"electrical_W": electrical / span, "damping_W": rate("damping_dissipated_J"),
                "friction_W": rate("stator_rotor_dissipated_J"), "output_W": float(np.mean(speed)) * load_N_m}


def window_means(means: dict[str, np.ndarray], window: int) -> dict[str, float]:
    return {k: float(np.mean(v[-window:])) for k, v in means.items() if k != "period"}


def compare(fe_dir: Path, modal_dirs: list[Path], frequency_Hz: float) -> dict:
    """The last-window means of the FE point and of each modal run (a modal setting per directory)."""
    rows = {}
    for label, directory in [("fe", fe_dir)] + [(d.name, d) for d in modal_dirs]:
        means = cycle_means(directory / "transient.h5", frequency_Hz)
        summary = json.loads((directory / "summary.json").read_text())["results"]["transient"]
        steady = summary.get("steady_state") or {}
        rows[label] = {"periods": int(means["period"].size), "steady": summary.get("steady", steady.get("steady")),
                       "wall_time_s": summary.get("wall_time_s"), "steps": summary.get("steps"),
                       **window_means(means, WINDOW), **window_powers(directory / "transient.h5", frequency_Hz, WINDOW)}
    fe = rows["fe"]
    for d in modal_dirs:
        rows[d.name]["vs_fe"] = {k: rows[d.name][k] / fe[k] - 1 for k in QUANTITIES}
    return rows


QUANTITIES = ("speed_rad_per_s", "torque_N_m", "normal_force_N", "wave_m")


def windows(fe_dir: Path, modal_dir: Path, frequency_Hz: float, length: int) -> None:
    """Both tiers' means over consecutive windows of ``length`` periods, as far as both have run: how the FE tier
    follows the modal tier through the start, before either is steady."""
    fe, modal = (cycle_means(d / "transient.h5", frequency_Hz) for d in (fe_dir, modal_dir))
    common = min(fe["period"].size, modal["period"].size)
    print(f"| periods | speed FE / modal [rpm] | torque FE / modal [mN m] | N FE / modal [N] | wave FE / modal [um] "
          f"| (of {common} both ran) |")
    print("|---|---|---|---|---|---|")
    for first in range(0, common, length):
        last = min(first + length, common)
        cells = []
        for key, scale in (("speed_rad_per_s", 30 / np.pi), ("torque_N_m", 1e3), ("normal_force_N", 1.0),
                       ("wave_m", 1e6)):
            a, b = fe[key][first:last].mean() * scale, modal[key][first:last].mean() * scale
            cells.append(f"{a:.3f} / {b:.3f} ({100 * (b / a - 1):+.2f} %)")
        print(f"| {first}-{last} | " + " | ".join(cells) + " | |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    fe = sub.add_parser("fe", help="run or resume the FE-tier point")
    fe.add_argument("--out", type=Path, required=True)
    fe.add_argument("--set", nargs="*", default=[], help="further --set overrides (the same on every resume)")
    cmp = sub.add_parser("compare", help="the FE and modal points' last-window cycle means")
    cmp.add_argument("--fe", type=Path, required=True)
    cmp.add_argument("--modal", type=Path, nargs="+", required=True, help="modal runs (one setting each)")
    win = sub.add_parser("windows", help="FE and modal means over windows of the periods both have run (an FE run "
                                         "still going: HDF5_USE_FILE_LOCKING=FALSE)")
    win.add_argument("--fe", type=Path, required=True)
    win.add_argument("--modal", type=Path, required=True)
    win.add_argument("--periods", type=int, default=50, help="window length [drive periods]")
    args = parser.parse_args()
    if args.command == "fe":
        results = run_fe(args.out, args.set)["results"]["transient"]
        print(json.dumps({k: results.get(k) for k in ("steps", "cutbacks", "newton_iterations", "wall_time_s",
                                                       "simulated_time_s", "steady_state")}, indent=1, default=str))
        return
    from app.runner import load_for_run

    frequency = load_for_run(CASE, POINT).transient.drive.frequency_Hz
    if args.command == "windows":
        windows(args.fe, args.modal, frequency, args.periods)
        return
    rows = compare(args.fe, args.modal, frequency)
    print(json.dumps(rows, indent=1))
    print(f"| run | periods | steady | speed [rpm] | friction torque [mN m] | normal force [N] | wave [um] | "
          f"(means over the last {WINDOW} periods; against FE) |")
    print("|---|---|---|---|---|---|---|---|")
    for label, r in rows.items():
        d = r.get("vs_fe")
        cells = []
        for key, scale, fmt in (("speed_rad_per_s", 30 / np.pi, ".3f"), ("torque_N_m", 1e3, ".4f"),
                                ("normal_force_N", 1.0, ".4f"), ("wave_m", 1e6, ".3f")):
            cells.append(f"{r[key] * scale:{fmt}}" + (f" ({100 * d[key]:+.1f} %)" if d else ""))
        print(f"| {label} | {r['periods']} | {r['steady']} | " + " | ".join(cells) + " | |")
    print(f"\n| run | electrical input [mW] | stator damping [mW] | friction [mW] | output [mW] | "
          f"(means over the last {WINDOW} periods) |")
    print("|---|---|---|---|---|---|")
    for label, r in rows.items():
        print(f"| {label} | {1e3 * r['electrical_W']:.2f} | {1e3 * r['damping_W']:.2f} | {1e3 * r['friction_W']:.2f} "
              f"| {1e3 * r['output_W']:.2f} | |")


if __name__ == "__main__":
    main()
