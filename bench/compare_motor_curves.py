"""Two speed-torque curves of the motor against each other (a mesh study of the curve, issue 24).

Reads two ``motor_curves.csv`` files of ``bench/bench_motor_curves.py`` (the reference, e.g. the case mesh, and a
finer mesh) and, per preload both hold, reports:

* the stall torques (the held rotors) and their difference relative to the reference stall torque;
* at every free point of the other curve, its speed against the reference curve's speed at the same load torque
  (linear interpolation between the reference's points: each curve's loads are fractions of its own stall torque,
  so the loads differ by the stall torques' difference), relative to the reference's no-load speed;
* at every free point, its load against the reference's stall torque (the torque axis's difference, relative to
  the reference stall torque as the issue states it: loads are k/n of each curve's stall).

    .venv/bin/python bench/compare_motor_curves.py REFERENCE.csv OTHER.csv [--tolerance 0.03]

Exit status 1 if a difference exceeds the tolerance (default 3 %: issue 24's criterion for the 2x-DOF mesh).
"""

from __future__ import annotations

import argparse
import csv
import sys

import numpy as np


def read_curves(path: str) -> dict[float, dict]:
    """preload [N] -> {"stall": load torque of the held rotor [N m], "load": free loads [N m], "speed": [rpm]}."""
    out: dict[float, dict] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            preload = float(row["preload_N"])
            curve = out.setdefault(preload, {"stall": None, "load": [], "speed": []})
            load, speed = float(row["load_torque_N_m"]), float(row["speed_rpm"])
            # the held rotor: bench_motor_curves.py writes its load as its friction torque, and a fixed rotation
            # has exactly zero speed (a free rotor near stall creeps)
            if speed == 0.0 and load > 0 and float(row["friction_torque_N_m"]) == load:
                curve["stall"] = load
            else:
                curve["load"].append(load)
                curve["speed"].append(speed)
    for curve in out.values():
        order = np.argsort(curve["load"])
        curve["load"] = np.asarray(curve["load"])[order]
        curve["speed"] = np.asarray(curve["speed"])[order]
    return out


def compare(reference: dict, other: dict) -> list[dict]:
    """Rows of differences (see the module docstring), per preload and point."""
    rows = []
    for preload in sorted(set(reference) & set(other)):
        ref, oth = reference[preload], other[preload]
        no_load = float(ref["speed"][0])
        stall = ref["stall"]
        rows.append({"preload_N": preload, "point": "stall", "reference": stall, "other": oth["stall"],
                     "relative": (oth["stall"] - stall) / stall})
        for load, speed in zip(oth["load"], oth["speed"]):
            at = float(np.interp(load, ref["load"], ref["speed"]))
            rows.append({"preload_N": preload, "point": f"{load * 1e3:.3f} mN m", "reference": at, "other": speed,
                         "relative": (speed - at) / no_load})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reference")
    parser.add_argument("other")
    parser.add_argument("--tolerance", type=float, default=0.03)
    args = parser.parse_args()
    rows = compare(read_curves(args.reference), read_curves(args.other))
    print("| preload [N] | point | reference | other | difference (of no-load speed / of stall) |")
    print("|---|---|---|---|---|")
    for r in rows:
        unit = "mN m" if r["point"] == "stall" else "rpm"
        scale = 1e3 if r["point"] == "stall" else 1.0
        print(f"| {r['preload_N']} | {r['point']} | {r['reference'] * scale:.2f} {unit} | {r['other'] * scale:.2f} "
              f"{unit} | {100 * r['relative']:+.2f} % |")
    worst = max(abs(r["relative"]) for r in rows)
    print(f"largest difference {100 * worst:.2f} % (tolerance {100 * args.tolerance:.1f} %)")
    sys.exit(0 if worst <= args.tolerance else 1)


if __name__ == "__main__":
    main()
