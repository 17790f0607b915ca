"""The contact depth on the inclined face (the paper's design lever): one figure and one CSV from motor runs at
several `geometry.parameters.contact_depth_m` (each with its contact circle `transient.contacts[0].radius_m` and the
rotor's apex height on the cone through it): the no-load rotor's speed [rpm] and the held rotor's torque [mN m]
against the depth [mm], with N and the contact's normal wave.

A point that did not settle (the window rule not met) is drawn at its last half's mean with its range as the error
bar (bench/bench_motor_tiers.py reads the runs the same way).

    .venv/bin/python bench/plot_motor_depth.py --out docs/figures/motor_depth --runs DIR ...
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_motor_tiers import run_point  # noqa: E402

KEYS = ("depth_mm", "contact_radius_mm", "held", "speed_rpm", "torque_mN_m", "level", "level_min", "level_max",
        "level_ci95", "steady", "periods", "normal_force_N", "wave_normal_um", "run")


def depth_row(directory: Path) -> dict:
    """One run's point with its contact depth [mm] and contact radius [mm]; ``level``: the last window's mean, or
    the last half's where it did not settle (speed [rpm] free, torque [mN m] held)."""
    summary = json.loads((directory / "summary.json").read_text())
    point = run_point(directory)
    value = point["torque_mN_m"] if point["held"] else point["speed_rpm"]
    settled = point["half_mean"] is None
    return {"depth_mm": summary["case"]["geometry"]["parameters"].get("contact_depth_m", 0.00126) * 1e3,
            "contact_radius_mm": summary["case"]["transient"]["contacts"][0]["radius_m"] * 1e3,
            "held": point["held"], "speed_rpm": point["speed_rpm"], "torque_mN_m": point["torque_mN_m"],
            "level": value if settled else point["half_mean"],
            "level_min": value if settled else point["half_min"],
            "level_max": value if settled else point["half_max"],
            "level_ci95": 0.0 if settled else point["half_ci95"], "steady": point["steady"],
            "periods": point["periods"], "normal_force_N": point["normal_force_N"],
            "wave_normal_um": point["wave_normal_um"], "run": directory.name}


def depth_figure(path: Path, rows: list[dict]) -> None:
    """Speed (free) and torque (held) against depth, then N and the wave; unsettled points with their range."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4), constrained_layout=True)
    for held, ax, label in ((False, axes[0], "no-load speed [rpm]"), (True, axes[1], "held rotor's torque [mN m]")):
        mine = sorted((r for r in rows if r["held"] == held), key=lambda r: r["depth_mm"])
        d = [r["depth_mm"] for r in mine]
        level = [r["level"] for r in mine]
        err = [[r["level"] - r["level_min"] for r in mine], [r["level_max"] - r["level"] for r in mine]]
        ax.errorbar(d, level, yerr=err, fmt="o-", capsize=4, label="last window (steady) / last half's mean and range")
        ax.set_xlabel("contact depth below the tip [mm]")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    for held, style in ((False, "o-"), (True, "s--")):
        mine = sorted((r for r in rows if r["held"] == held), key=lambda r: r["depth_mm"])
        name = "held" if held else "no load"
        axes[2].plot([r["depth_mm"] for r in mine], [r["normal_force_N"] for r in mine], style, label=f"N, {name}")
        axes[2].plot([r["depth_mm"] for r in mine], [r["wave_normal_um"] for r in mine], style, alpha=0.5,
                     label=f"normal wave [µm], {name}")
    axes[2].set_yscale("log")
    axes[2].set_xlabel("contact depth below the tip [mm]")
    axes[2].set_ylabel("N [N], wave [µm]")
    axes[2].grid(True, alpha=0.3)
    axes[2].legend(fontsize=7)
    fig.suptitle("WW-USM at 0.98 N, 400 Vpp, modal tier (case mesh): where on the inclined face the rotor touches")
    fig.savefig(path.with_suffix(".png"), dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="figure and CSV path without suffix")
    ap.add_argument("--runs", nargs="+", required=True, help="motor result directories (free and held rotors)")
    args = ap.parse_args()
    rows = sorted((depth_row(Path(d)) for d in args.runs), key=lambda r: (r["held"], r["depth_mm"]))
    out = Path(args.out)
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=KEYS)
        writer.writeheader()
        writer.writerows({k: r[k] for k in KEYS} for r in rows)
    depth_figure(out, rows)
    for r in rows:
        print(f"{r['run']}: depth {r['depth_mm']:.2f} mm, r_c {r['contact_radius_mm']:.4f} mm, "
              f"{'held' if r['held'] else 'free'}: {r['level']:.2f} ({r['level_min']:.2f}–{r['level_max']:.2f}, "
              f"± {r['level_ci95']:.2f}), N {r['normal_force_N']:.2f} N, wave {r['wave_normal_um']:.3f} um")
    print(f"figure and CSV: {out.with_suffix('.png')}, {out.with_suffix('.csv')}")


if __name__ == "__main__":
    main()
