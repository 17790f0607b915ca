"""One figure and one CSV of the motor's frequency characteristic from several sweeps of
bench/bench_motor_frequency.py (each a ``motor_frequency.csv``, labelled by its branch) and the lumped tier's curve
(``motor_frequency_lumped.csv``): rotor speed [rpm] and the contact's normal amplitude [um] against the detuning
from the model's F(1,4) [Hz], the up and down sweeps marked.

    .venv/bin/python bench/plot_motor_frequency.py --out docs/figures/motor_frequency \
        --sweep wedged=/work/runs/freq-rest --sweep wedged=/work/runs/freq-rest-up \
        --sweep riding=/work/runs/freq-riding --lumped /work/runs/freq-riding/motor_frequency_lumped.csv
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

KEYS = ("branch", "direction", "detuning_Hz", "detuning_bandwidths", "frequency_Hz", "speed_rpm", "normal_force_N",
        "normal_amplitude_um", "tangential_amplitude_um", "electrical_power_W", "separation", "stick",
        "forward_slip", "backward_slip", "steady", "periods")


def read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


TITLE = "WW-USM at 0.98 N, no load, modal tier (case mesh): the frequency characteristic on both branches"


def frequency_figure(path: Path, rows: list[dict], lumped: list[dict] | None = None, title: str = TITLE) -> None:
    """Speed [rpm] and normal amplitude [um] against detuning [Hz]: a row of panels per branch in ``rows`` (each row a
    sweep point with ``branch``, ``direction``, ``detuning_Hz``, ``speed_rpm``, ``normal_amplitude_um``), the lumped
    tier's curve with the riding branch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    branches = list(dict.fromkeys(r["branch"] for r in rows)) or ["riding"]
    fig, axes = plt.subplots(len(branches), 2, figsize=(11, 3.5 * len(branches)), constrained_layout=True,
                             sharex=True, squeeze=False)
    for ax_row, branch in enumerate(branches):
        colour = "C3" if branch == "riding" else f"C{ax_row}"
        for direction, style in (("up", "o-"), ("down", "s--")):
            mine = sorted((r for r in rows if r["branch"] == branch and r["direction"] == direction),
                          key=lambda r: float(r["detuning_Hz"]))
            if not mine:
                continue
            d = [float(r["detuning_Hz"]) for r in mine]
            label = f"{branch}, swept {direction}"
            axes[ax_row, 0].plot(d, [float(r["speed_rpm"]) for r in mine], style, color=colour, label=label)
            axes[ax_row, 1].plot(d, [float(r["normal_amplitude_um"]) for r in mine], style, color=colour,
                                 label=label)
    if lumped:
        d = [float(r["detuning_Hz"]) for r in lumped]
        riding = branches.index("riding") if "riding" in branches else len(branches) - 1
        axes[riding, 0].plot(d, [float(r["speed_rpm"]) for r in lumped], "k:", label="lumped tier (riding root)")
        axes[riding, 1].plot(d, [float(r["normal_amplitude_um"]) for r in lumped], "k:",
                             label="lumped tier (riding root)")
    for row, branch in enumerate(branches):
        axes[row, 0].set(ylabel=f"{branch}: rotor speed [rpm]")
        axes[row, 1].set(ylabel=f"{branch}: normal amplitude at the contact [um]")
    for ax in axes[-1]:
        ax.set(xlabel="drive frequency - model F(1,4) [Hz]")
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="path without suffix: writes OUT.csv and OUT.png")
    parser.add_argument("--sweep", action="append", default=[], metavar="BRANCH=DIR",
                        help="a sweep's directory (its motor_frequency.csv) and the branch it follows")
    parser.add_argument("--lumped", default=None, help="the lumped tier's motor_frequency_lumped.csv")
    args = parser.parse_args()
    rows = []
    for item in args.sweep:
        branch, directory = item.split("=", 1)
        for r in read(Path(directory) / "motor_frequency.csv"):
            rows.append({"branch": branch, **{k: r[k] for k in KEYS[1:]}})
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=KEYS)
        writer.writeheader()
        writer.writerows(rows)

    frequency_figure(out.with_suffix(".png"), rows, read(Path(args.lumped)) if args.lumped else None)
    print(f"wrote {out.with_suffix('.csv')} ({len(rows)} points) and {out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
