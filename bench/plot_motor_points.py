"""Speed-torque points of the motor by preload and branch, from a points CSV (docs/figures/motor_points_issue24.csv:
columns preload_N, branch, load_torque_N_m, speed_rpm, electrical_power_W; held rotors are the rows at zero speed).

    .venv/bin/python bench/plot_motor_points.py docs/figures/motor_points_issue24.csv \
        docs/figures/motor_points_issue24.png
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    parser.add_argument("png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = defaultdict(list)
    with open(args.csv, newline="") as f:
        for row in csv.DictReader(f):
            key = (float(row["preload_N"]), row["branch"], row.get("mesh_refinement", ""))
            curves[key].append((1e3 * float(row["load_torque_N_m"]), float(row["speed_rpm"]),
                                float(row["electrical_power_W"])))
    fig, (speed_ax, power_ax) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for (preload, branch, refinement), points in sorted(curves.items()):
        points.sort()
        label = f"{preload:g} N, {branch}" + (f", mesh_refinement {refinement}" if refinement else "")
        style = "o-" if branch == "wedged" else "s--"
        speed_ax.plot([p[0] for p in points], [p[1] for p in points], style, ms=4, label=label)
        power_ax.plot([p[0] for p in points], [p[2] for p in points], style, ms=4, label=label)
    speed_ax.set(xlabel="load torque [mN m] (held rotor: speed 0)", ylabel="rotor speed [rpm]")
    speed_ax.set_yscale("symlog", linthresh=10.0)
    power_ax.set(xlabel="load torque [mN m]", ylabel="electrical power drawn [W]", yscale="log")
    for ax in (speed_ax, power_ax):
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(loc="best", fontsize=8)
    fig.suptitle("WW-USM on the issue-24 stator, modal tier, 400 Vpp at the locked F(1,4): the riding and the "
                 "wedged branch", fontsize=10)
    fig.savefig(args.png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
