"""Convergence of the modal motor's contact sampling (docs/motor-rotor.md, "Contact sampling").

Each point is the motor case (cases/wwusm-motor.toml) in the modal tier with the rotor's spin prescribed
(``constant_rate``) or free, run for a fixed number of drive periods; the result is the mean over the last
``--window`` periods. Samplings are ``RING:POINTS`` pairs: RING interface nodes of the reduced stator
(``reduction.ring_points``, a basis each, cached) and POINTS contact points (``reduction.contact_points``;
0 = at the nodes). The start's transient (the wave decaying from its free amplitude, 8 um, to the loaded one,
with a lift-off of the rotor) lasts 350-700 periods at 0.98 N, so for each RING the first point runs
``--settle`` periods from the harmonic start, and every other point of that RING continues from its end state
(``motor_state.npz``, the same reduced model) for ``--periods`` periods. Prints one JSON line per point and a
Markdown table.

    .venv/bin/python bench/bench_motor_sampling.py --out /tmp/motor_sampling --rpm 0 40 \\
        --sampling 64:0 64:64 64:128 64:256 64:512 128:0 128:512
    .venv/bin/python bench/bench_motor_sampling.py --free --periods 1500 --window 100 --sampling 64:512 128:512
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASE = ROOT / "cases" / "wwusm-motor.toml"
PERIOD_S = 1 / 36065.0


def cycle_means(h5_path: Path, name: str, per_period: int, column: int | None = None) -> np.ndarray:
    import h5py

    with h5py.File(h5_path, "r") as f:
        data = f[name][:]
    if column is not None:
        data = data[:, column]
    k = data.size // per_period
    return data[:k * per_period].reshape(k, per_period).mean(axis=1)


def point(out: Path, ring: int, points: int, rpm: float | None, periods: int, window: int, extra: list[str],
          warm_start: Path | None) -> dict:
    from app.reduced.motor import run_continued

    sets = [f"reduction.ring_points={ring}", f"reduction.contact_points={points}",
            f"transient.end_time_s={periods * PERIOD_S * (1 + 1e-6)!r}",
            f"transient.steady_state.window_cycles={window}",
            "transient.steady_state.relative_tolerance=1e-9",       # run all the periods: the mean is over the window
            "output.plots=false"] + extra
    if rpm is not None:
        sets += ['transient.bodies[0].rotations[0].motion="constant_rate"',
                 f"transient.bodies[0].rotations[0].rate_rad_per_s={rpm * 2 * math.pi / 60!r}"]
    start = time.perf_counter()
    tr = run_continued(CASE, sets, out, warm_start)
    wall = time.perf_counter() - start
    m = tr["motor"]
    per = tr["steps_per_period"]
    torque = cycle_means(out / tr["time_series"], "stator_rotor_torque_N_m", per)[-window:]
    speed = cycle_means(out / tr["time_series"], "rotor_angular_velocity_rad_per_s", per, 0)[-window:]
    half = window // 2
    return {"ring_points": ring, "contact_points": points, "rpm_prescribed": rpm,
            "warm_start": str(warm_start) if warm_start else None,
            "torque_mN_m": m["friction_torque_N_m"] * 1e3, "speed_rpm": m["speed_rpm"],
            # drift: the window's second half against its first (a slow creep shows here)
            "torque_drift_mN_m": (torque[half:].mean() - torque[:half].mean()) * 1e3,
            "speed_drift_rpm": (speed[half:].mean() - speed[:half].mean()) * 60 / (2 * math.pi),
            "torque_ripple_mN_m": float(np.std(torque)) * 1e3,
            "normal_force_N": m["normal_force_N"], "separation": m["fractions"]["separation"],
            "electrical_power_mW": m["electrical_power_W"] * 1e3, "periods": tr["periods"],
            "loop_s": tr["wall_time_s"], "ms_per_step": 1e3 * tr["wall_time_s"] / tr["steps"], "wall_s": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/motor_sampling")
    parser.add_argument("--sampling", nargs="+", default=["64:0", "64:128", "64:256", "64:512"],
                        help="RING:POINTS pairs (POINTS 0: at the ring nodes)")
    parser.add_argument("--rpm", type=float, nargs="+", default=[0.0, 40.0], help="prescribed speeds [rpm]")
    parser.add_argument("--free", action="store_true", help="a free rotor at no load instead of prescribed speeds")
    parser.add_argument("--settle", type=int, default=700, help="periods of each RING's first point (harmonic start)")
    parser.add_argument("--periods", type=int, default=300, help="periods of the other points (continued)")
    parser.add_argument("--window", type=int, default=200, help="periods averaged at the end")
    parser.add_argument("--set", nargs="*", default=[], help="further --set overrides for every point")
    parser.add_argument("--warm-start", nargs="*", default=[], metavar="RING=STATE",
                        help="continue RING's first point from this motor_state.npz (instead of the harmonic start)")
    args = parser.parse_args()
    out = Path(args.out)
    rows = []
    speeds = [None] if args.free else args.rpm
    settled = {int(ring): Path(path) for ring, path in (item.split("=") for item in args.warm_start)}
    for pair in args.sampling:
        ring, points = (int(x) for x in pair.split(":"))
        for rpm in speeds:
            name = f"n{ring}_c{points}_" + ("free" if rpm is None else f"rpm{rpm:g}")
            warm = settled.get(ring)
            row = point(out / name, ring, points, rpm, args.periods if warm else args.settle, args.window, args.set,
                        warm)
            settled.setdefault(ring, out / name / "motor_state.npz")
            rows.append(row)
            print(json.dumps(row), flush=True)
    (out / "sampling.json").write_text(json.dumps(rows, indent=1))
    print("| ring nodes | contact points | speed [rpm] | torque [mN m] | drift [mN m] | N [N] | separation | "
          "ms/step |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        points = r["contact_points"] or f"{r['ring_points']} (nodes)"
        print(f"| {r['ring_points']} | {points} | {r['speed_rpm']:.2f} | {r['torque_mN_m']:.3f} | "
              f"{r['torque_drift_mN_m' if r['rpm_prescribed'] is not None else 'speed_drift_rpm']:+.3f} | "
              f"{r['normal_force_N']:.3f} | {r['separation']:.3f} | {r['ms_per_step']:.2f} |")


if __name__ == "__main__":
    main()
