"""The motor's frequency characteristic: rotor speed against drive frequency, swept up and then down.

The case's drive is locked to its model's F(1,4) (``transient.drive.lock = "resonance"``), so a sweep is a sweep
of ``transient.drive.detuning_Hz``: the reduced stator is built once (its cache key holds no drive frequency).
The sweep runs from the lowest detuning to the highest and back, each point a warm start from the previous
point's end state (``transient.start_from``; the drive's phase is kept continuous across the change of
frequency, as a swept generator does), so the branch the motor is on is followed, as in a measurement with a
slow sweep (``--from-centre``: from the resonance up, then from the resonance down). The first point starts
from the case's own start (``--start rest`` or ``harmonic``), which picks the branch (docs/motor-rotor.md,
"Two branches"). Each point runs to the steady-state rule the ``--set`` options give
(default: the trend rule, no fixed minimum).

    .venv/bin/python bench/bench_motor_frequency.py --out /tmp/motor_frequency --start rest \
        [--bandwidths 3] [--step-bandwidths 0.5] [--case cases/wwusm-motor.toml] [--set KEY=VALUE ...]
    .venv/bin/python bench/bench_motor_frequency.py --out /tmp/motor_frequency_up --warm-from DIR --up-from 3 \
        --up-to 15 --step-bandwidths 2      (an extension upwards from the end state of the point in DIR)

Run again with the same ``--out``, a sweep reuses the points it finished and resumes the one it was stopped in.
Writes ``motor_frequency.csv`` (one row per point: direction, detuning [Hz], detuning in half-power bandwidths,
drive frequency [Hz], speed [rpm], normal force [N], the probe's normal amplitude [um], electrical power [W],
contact fractions, periods, wall time [s]) and ``motor_frequency.png``.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.runner import run_case  # noqa: E402

CASE = ROOT / "cases" / "wwusm-motor.toml"
COLUMNS = ("direction", "detuning_Hz", "detuning_bandwidths", "frequency_Hz", "speed_rpm", "normal_force_N",
           "normal_amplitude_um", "tangential_amplitude_um", "electrical_power_W", "friction_torque_N_m",
           "separation", "stick", "forward_slip", "backward_slip", "steady", "periods", "wall_s", "warm_from")


def run_point(case: Path, out: Path, sets: list[str], warm_from: Path | None) -> dict:
    """One point of the sweep; its row from the motor scene's statistics and the drive record."""
    start = time.perf_counter()
    if warm_from is not None:
        sets = sets + [f"transient.start_from={str(Path(warm_from).resolve())!r}"]
    summary = out / "summary.json"
    if summary.exists():                                   # a point of an earlier, interrupted sweep: reused
        tr = json.loads(summary.read_text())["results"]["transient"]
    else:                                                  # resumed from its checkpoint if it was interrupted
        resume = (out / "checkpoint" / "checkpoint.json").exists()
        tr = run_case(case, sets, out, quiet=True, resume=resume)["results"]["transient"]
    m = tr["statistics"]["motor"]
    steady = tr.get("steady_state", {})
    amplitude = m.get("contact_point_amplitude_m", {})
    row = {"frequency_Hz": tr["drive"]["frequency_Hz"], "speed_rpm": m["speed_rpm"],
           "normal_force_N": m["normal_force_N"], "normal_amplitude_um": 1e6 * amplitude.get("normal", float("nan")),
           "tangential_amplitude_um": 1e6 * amplitude.get("tangential", float("nan")),
           "electrical_power_W": m["electrical_power_W"], "friction_torque_N_m": m["friction_torque_N_m"],
           "steady": bool(steady.get("steady")), "periods": steady.get("cycles"),
           "wall_s": time.perf_counter() - start, "warm_from": Path(warm_from).name if warm_from else ""}
    row.update(m["fractions"])
    return row


def lumped_sweep(case: Path, out: Path, sets: list[str], resonance_Hz: float, detunings_Hz) -> list[dict]:
    """The lumped tier (``tier = "lumped"``, the friction-drive law on the F(1,4) pair: docs/lumped-motor.md) at
    the same detunings from ``resonance_Hz``: its no-load speed on the upper (riding) branch, and the lower root
    where it exists. ``sets`` type the stator's data (bench/motor_lumped_parameters.py on the modal case's reduced
    stator)."""
    rows = []
    for d in detunings_Hz:
        res = run_case(case, sets + [f"lumped.drive.frequency_Hz={resonance_Hz + d!r}"], out / f"lumped{d:+.1f}",
                       quiet=True)["results"]
        m = res["transient"]["statistics"]["motor"] if "transient" in res else res["lumped"]["statistics"]["motor"]
        rows.append({"detuning_Hz": d, "speed_rpm": m["speed_rpm"],
                     "normal_amplitude_um": 1e6 * m.get("wave_amplitude_m", float("nan"))})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/motor_frequency")
    parser.add_argument("--case", default=str(CASE))
    parser.add_argument("--start", choices=("rest", "harmonic"), default="rest",
                        help="the first point's start: from rest (the stator rings up under the rotor) or the "
                             "stator's free harmonic state")
    parser.add_argument("--bandwidths", type=float, default=3.0, help="sweep range: +- this many half-power "
                                                                      "bandwidths 2 zeta f")
    parser.add_argument("--step-bandwidths", type=float, default=0.5, help="spacing of the points [bandwidths]")
    parser.add_argument("--zeta", type=float, default=0.002, help="the stator's damping ratio at F(1,4) (the "
                                                                   "paper's 0.2 %%): sets the bandwidth")
    parser.add_argument("--set", nargs="*", default=[], help="further --set overrides for every point")
    parser.add_argument("--from-centre", action="store_true",
                        help="start at the resonance (detuning 0) and sweep up from there, then down from there "
                             "(the branch the start reaches at resonance, as far as it persists either way)")
    parser.add_argument("--warm-from", default=None, help="the first point starts from this run's end state")
    parser.add_argument("--up-from", type=float, default=0.0, help="with --up-to: the detuning [bandwidths] of the "
                                                                    "--warm-from run")
    parser.add_argument("--up-to", type=float, default=None, help="sweep only up, from --up-from (exclusive) to this "
                                                                   "detuning [bandwidths], from --warm-from")
    parser.add_argument("--lumped-case", default=None, help="a lumped friction_drive case to sweep beside it")
    parser.add_argument("--lumped-set", nargs="*", default=[], help="--set overrides of the lumped case (its "
                                                                     "stator's data)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = Path(args.case)
    from app.runner import load_for_run

    base = [f'transient.initial_state="{args.start}"'] + args.set
    if not any(s.startswith("transient.steady_state.rule") for s in base):
        base.append('transient.steady_state.rule="trend"')
    nominal = load_for_run(case, base).transient.drive.frequency_Hz
    bandwidth_Hz = 2 * args.zeta * nominal
    n = int(round(args.bandwidths / args.step_bandwidths))
    steps = [k * args.step_bandwidths for k in range(-n, n + 1)]
    if args.up_to is not None:      # an extension of a sweep upwards from an earlier point's end state
        k = 1
        steps = []
        while args.up_from + k * args.step_bandwidths <= args.up_to + 1e-9:
            steps.append(args.up_from + k * args.step_bandwidths)
            k += 1
        schedule = [("up", b) for b in steps]
    elif args.from_centre:      # the branch the start reaches at the resonance, followed up, then down from there
        schedule = [("up", b) for b in steps[n:]] + [("down", b) for b in reversed(steps[:n])]
    else:
        schedule = [("up", b) for b in steps] + [("down", b) for b in reversed(steps[:-1])]
    rows, previous = [], (Path(args.warm_from) if args.warm_from else None)
    started = time.perf_counter()
    for i, (direction, b) in enumerate(schedule):
        if args.from_centre and direction == "down" and b == steps[n - 1]:
            previous = out / f"{0:02d}-up-{steps[n]:+.2f}bw"
        detuning = b * bandwidth_Hz
        name = f"{i:02d}-{direction}-{b:+.2f}bw"
        row = run_point(case, out / name, base + [f"transient.drive.detuning_Hz={detuning!r}"], previous)
        row.update(direction=direction, detuning_Hz=detuning, detuning_bandwidths=b)
        rows.append(row)
        previous = out / name
        print(f"{direction:>4} {detuning:+8.1f} Hz ({b:+.2f} bw): {row['speed_rpm']:9.3f} rpm, N "
              f"{row['normal_force_N']:.3f} N, wave {row['normal_amplitude_um']:.3f} um, "
              f"{row['electrical_power_W']:.3g} W, steady {row['steady']} after {row['periods']} periods, "
              f"{row['wall_s']:.0f} s", flush=True)
    with open(out / "motor_frequency.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row[k] for k in COLUMNS})
    lumped = None
    if args.lumped_case:
        first = steps[n] if args.from_centre and args.up_to is None else steps[0]
        resonance = json.loads((out / f"00-up-{first:+.2f}bw" / "summary.json").read_text())[
            "results"]["transient"]["drive"]["resonance_Hz"]
        fine = [k * bandwidth_Hz / 8 for k in range(-8 * n, 8 * n + 1)] if n else [0.0]
        fine = [d * args.step_bandwidths for d in fine]
        lumped = lumped_sweep(Path(args.lumped_case), out / "lumped", args.lumped_set, resonance, fine)
        with open(out / "motor_frequency_lumped.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=("detuning_Hz", "speed_rpm", "normal_amplitude_um"))
            writer.writeheader()
            writer.writerows(lumped)
    from bench.plot_motor_frequency import frequency_figure

    branch = f"from {args.start}"
    frequency_figure(out / "motor_frequency.png", [dict(r, branch=branch) for r in rows], lumped,
                     f"WW-USM, modal tier: frequency characteristic from {args.start}, bandwidth {bandwidth_Hz:.0f} Hz")
    report = {"points": len(rows), "wall_s": time.perf_counter() - started, "bandwidth_Hz": bandwidth_Hz,
              "start": args.start, "sets": base}
    (out / "motor_frequency.json").write_text(json.dumps({"report": report, "rows": rows}, indent=1))
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
