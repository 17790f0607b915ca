"""Speed-torque points of the motor by preload and branch, from a points CSV: the issue-24 points
(docs/figures/motor_points_issue24.csv: columns preload_N, branch, load_torque_N_m, speed_rpm, electrical_power_W;
held rotors are the rows at zero speed) or the curves of ``bench/motor_curves_csv.py`` (docs/figures/motor_curves.csv:
load_mN_m, held, speed_rpm or, where a point did not settle, its last half's mean half_mean, output_power_mW,
efficiency_pct; the held rotor at its torque). The second panel is the output power where the CSV has it (points
the load turns backwards left out), else the electrical power drawn.

    .venv/bin/python bench/plot_motor_points.py docs/figures/motor_points_issue24.csv \
        docs/figures/motor_points_issue24.png
    .venv/bin/python bench/plot_motor_points.py docs/figures/motor_curves.csv docs/figures/motor_curves.png
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
        rows = list(csv.DictReader(f))
    output = bool(rows) and "output_power_mW" in rows[0]
    for row in rows:
        key = (float(row["preload_N"]), row["branch"], row.get("mesh_refinement", ""))
        curves[key].append(_point(row) if output else (1e3 * float(row["load_torque_N_m"]), float(row["speed_rpm"]),
                                                       float(row["electrical_power_W"]), False))
    fig, (speed_ax, power_ax) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for (preload, branch, refinement), points in sorted(curves.items()):
        points.sort()
        label = f"{preload:g} N, {branch}" + (f", mesh_refinement {refinement}" if refinement else "")
        style = "o-" if branch == "wedged" else "s--"
        free = [p for p in points if not p[3]]
        line, = speed_ax.plot([p[0] for p in free], [p[1] for p in free], style, ms=4, label=label)
        held = [p for p in points if p[3]]           # the held rotor: its torque, apart from the free points' line
        if held:
            speed_ax.plot([p[0] for p in held], [p[1] for p in held], "*", ms=10, color=line.get_color(),
                          label=f"{label}, held")
        shown = [p for p in free if p[2] is not None and p[2] > 0.0]
        power_ax.plot([p[0] for p in shown], [p[2] for p in shown], style, ms=4, label=label)
    speed_ax.set(xlabel="load torque [mN m] (held rotor: its torque at speed 0)", ylabel="rotor speed [rpm]")
    speed_ax.set_yscale("symlog", linthresh=10.0)
    power_ax.set(xlabel="load torque [mN m]", ylabel="output power [W]" if output else "electrical power drawn [W]",
                 yscale="log")
    for ax in (speed_ax, power_ax):
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(loc="best", fontsize=8)
    fig.suptitle("WW-USM on the issue-24 stator, modal tier, 400 Vpp at the locked F(1,4): the riding and the "
                 "wedged branch", fontsize=10)
    fig.savefig(args.png, dpi=110)
    plt.close(fig)


def _point(row: dict) -> tuple:
    """(load [mN m], speed [rpm], output power [W] or None, held) of a motor_curves.csv row: a held rotor at its
    torque and zero speed; a point that did not settle at its last half's mean speed; no output where the load turns
    the rotor backwards."""
    held = row["held"] == "True"
    speed = float(row["half_mean"]) if row["steady"] != "True" and row["half_mean"] and not held \
        else float(row["speed_rpm"])
    rippling = held and row["steady"] != "True" and row["half_mean"]     # a held torque's last half, as the table
    load = float(row["half_mean"] if rippling else row["torque_mN_m"] if held else row["load_mN_m"])
    power = 1e-3 * float(row["output_power_mW"]) if speed > 0.0 and not held else None
    return load, 0.0 if held else speed, power, held


if __name__ == "__main__":
    main()
