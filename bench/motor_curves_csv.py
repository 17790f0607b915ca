"""The motor's speed–torque curves as one table: a row per point, every preload and branch (issue 24).

Each ``--curve PRELOAD_N BRANCH START RUN_DIR ...`` names one curve: its preload [N], the branch it follows
(``riding``, ``wedged``), how its points were started (free text, e.g. "rest, chained up") and the result
directories of `piezodyn run` that are its points (summary.json; a held rotor's point is the curve's stall). A point
that did not meet the window rule is given by the mean of its last half (± 95 % from batch means, and the range:
``bench/bench_motor_tiers.py``'s ``run_point``). Prints a markdown table and, per curve, what a designer reads
first: the no-load speed, the stall (the held rotor's torque, or the bracket between the heaviest load that still
turns forward and the lightest that does not), the largest output power and efficiency, and the stall against
μ_k N r_c with the paper's N = P / sin 15°; writes the rows to ``--csv``.

    .venv/bin/python bench/motor_curves_csv.py --csv docs/figures/motor_curves.csv \\
        --curve 0.98 wedged "rest, chained up" W0-free C098-20 ... \\
        --curve 4.116 wedged "harmonic, rotor at 60 rpm" P4.116_T0 r0.6_T20.164 ... P4.116_stall
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_motor_tiers import _level, run_point  # noqa: E402

COLUMNS = ["preload_N", "branch", "start", "load_mN_m", "held", "speed_rpm", "steady", "periods", "half_mean",
           "half_ci95", "half_min", "half_max", "torque_mN_m", "normal_force_N", "wave_normal_um", "output_power_mW",
           "electrical_power_mW", "efficiency_pct", "kinetic_friction_bound_mN_m", "run"]


def curve_rows(preload: float, branch: str, start: str, directories: list[str]) -> list[dict]:
    """The curve's points, lightest load first and the held rotor last."""
    rows = []
    for directory in directories:
        row = run_point(Path(directory))
        motor = json.loads((Path(directory) / "summary.json").read_text())["results"]["transient"]["statistics"][
            "motor"]
        row.update(preload_N=preload, branch=branch, start=start,
                   # μ_k N r_c with the paper's N = P / sin 15° (the law's stall; the run's N is in normal_force_N)
                   kinetic_friction_bound_mN_m=1e3 * motor["kinetic_friction_torque_N_m"],
                   run=Path(directory).name)
        rows.append(row)
    return sorted(rows, key=lambda r: (r["held"], r["load_mN_m"]))


def level(row: dict) -> float:
    """A free point's speed [rpm]: its last window's mean, or its last half's where it did not settle."""
    return _level(row, "speed_rpm")


def designer_summary(rows: list[dict]) -> str:
    """No-load speed, stall, peak output power and efficiency of one curve."""
    free = [r for r in rows if not r["held"]]
    held = [r for r in rows if r["held"]]
    forward = [r for r in free if level(r) > 0.0]
    backward = [r for r in free if level(r) <= 0.0]
    bound = rows[0]["kinetic_friction_bound_mN_m"]
    parts = [f"{rows[0]['preload_N']} N, {rows[0]['branch']}: {len(forward)} turning points"]
    no_load = next((r for r in free if abs(r["load_mN_m"]) < 1e-9), None)
    if no_load:
        parts.append(f"no-load {level(no_load):.2f} rpm")
    if forward and backward:
        low = max(r["load_mN_m"] for r in forward)
        high = min(r["load_mN_m"] for r in backward if r["load_mN_m"] > low) if any(
            r["load_mN_m"] > low for r in backward) else None
        if high is not None:
            parts.append(f"pull-out between {low:.1f} and {high:.1f} mN m ({low / bound:.2f}–{high / bound:.2f} "
                         f"x mu_k N r_c = {bound:.1f} mN m)")
    for r in held:
        if r["steady"] or r["half_mean"] is None:
            parts.append(f"held {r['torque_mN_m']:.2f} mN m ({r['torque_mN_m'] / bound:.2f} x mu_k N r_c)")
        else:       # a held torque that ripples: its last half's mean, not the last window's
            parts.append(f"held {r['half_mean']:.2f} ± {r['half_ci95']:.2f} mN m over its last half "
                         f"({r['half_mean'] / bound:.2f} x mu_k N r_c; last window {r['torque_mN_m']:.2f})")
    if forward:
        best = max(forward, key=lambda r: r["output_power_mW"])
        parts.append(f"output peak {best['output_power_mW']:.0f} mW at {best['load_mN_m']:.1f} mN m")
        best = max(forward, key=lambda r: r["efficiency_pct"])
        parts.append(f"efficiency peak {best['efficiency_pct']:.1f} % at {best['load_mN_m']:.1f} mN m")
    return "; ".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--curve", nargs="+", action="append", required=True,
                    metavar="PRELOAD_N BRANCH START RUN_DIR", help="one curve: preload, branch, start, its runs")
    ap.add_argument("--csv", help="write the rows here")
    args = ap.parse_args()
    curves = []
    for item in args.curve:
        if len(item) < 4:
            ap.error("--curve needs PRELOAD_N BRANCH START and at least one RUN_DIR")
        curves.append(curve_rows(float(item[0]), item[1], item[2], item[3:]))
    print("| preload [N] | branch | load [mN m] | speed [rpm] | last half: mean ± 95 % (range) | N [N] | "
          "wave [µm] | out / drawn [mW] | efficiency | periods (steady) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for rows in curves:
        for r in rows:
            half = ("-" if r["half_mean"] is None or r["steady"] else
                    f"{r['half_mean']:.2f} ± {r['half_ci95']:.2f} ({r['half_min']:.2f}–{r['half_max']:.2f})")
            load = f"held: {r['torque_mN_m']:.2f}" if r["held"] else f"{r['load_mN_m']:.3f}"
            # a point the load turns backwards gives no output: its power balance is not a motor's
            forward = r["held"] or level(r) > 0.0
            power = (f"{r['output_power_mW'] or 0.0:.0f} / {r['electrical_power_mW']:.0f}" if forward
                     else f"– / {r['electrical_power_mW']:.0f}")
            efficiency = f"{r['efficiency_pct'] or 0.0:.1f} %" if forward and not r["held"] else "–"
            print(f"| {r['preload_N']} | {r['branch']} | {load} | {r['speed_rpm']:.2f} | {half} | "
                  f"{r['normal_force_N']:.2f} | {r['wave_normal_um']:.2f} | "
                  f"{power} | {efficiency} | "
                  f"{r['periods']} ({'yes' if r['steady'] else 'no'}) |")
    print()
    for rows in curves:
        print("- " + designer_summary(rows))
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS)
            writer.writeheader()
            for rows in curves:
                writer.writerows({k: r.get(k) for k in COLUMNS} for r in rows)
        print(f"table: {args.csv}")


if __name__ == "__main__":
    main()
