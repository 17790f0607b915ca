"""Speed-torque curves of the wedge-wave motor in the modal tier, at the paper's two preloads.

For each preload (0.98 N and 4.116 N): the held rotor (rotation fixed) gives the stall torque T_s, then a
free rotor under load torques T_s * k / n (k = 0 .. n-1) gives the curve: speed, output power T_L Omega,
electrical power from the electrode charges, efficiency, contact-state fractions, energy balance. Every
point is ``piezodyn run cases/wwusm-motor.toml`` with ``--set`` overrides (the reduced stator comes from the
cache after the first point), run until the cycle-mean speed (or torque) changes by less than 0.5 % over
20 periods. The peer for cost is the FE tier on the same case: its per-step time (``--fe-step-s``, measured
by an FE run of the case, see BENCHMARKS.md) times the steps the modal tier took gives the FE-tier cost of
the same curves.

    .venv/bin/python bench/bench_motor_curves.py --out /tmp/motor_curves [--points 8] [--fe-step-s 2.0]
        [--preloads 4.116] [--chain up|down] [--case bench/cases/wwusm-motor-pinned.toml]
        [--set 'transient.contacts[0].sample_points=256' ...]

Without ``--chain`` each point starts from the case's start (the stator's harmonic state or rest, the rotor
seated), and pays the start's transient (300-700 periods on the case mesh). ``--chain down`` runs the held
rotor, then the loads from the heaviest down, each from the previous point's end state
(``transient.start_from``, a warm start: docs/transient.md, "Warm starts"); ``--chain up`` runs the held rotor
and the no-load point from the case's start, then each heavier load from the previous one. Where the motor is
bistable the two directions may follow different branches (docs/motor-studies.md, "Two regimes").
A warm start pays only with a rule that has no fixed minimum: ``--set 'transient.steady_state.rule="trend"'``
(docs/transient.md, "Steady-state stop"; measured on the coarse stator in BENCHMARKS.md, "Motor curve: the trend
steady-state rule and warm starts").
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
PRELOADS_N = (0.98, 4.116)
COLUMNS = ("preload_N", "load_torque_N_m", "speed_rpm", "speed_rad_per_s", "friction_torque_N_m", "output_power_W",
           "electrical_power_W", "efficiency", "normal_force_N", "coulomb_torque_bound_N_m", "separation", "stick",
           "forward_slip", "backward_slip", "energy_balance_relative", "steady", "periods", "steps", "cutbacks",
           "wall_s", "warm_from")


def point(out: Path, sets: list[str], warm_from: Path | None = None, case: Path = CASE) -> dict:
    """One operating point: ``piezodyn run`` of the case with ``sets`` (from the end state of the run in
    ``warm_from`` if given); its row (the motor scene's statistics)."""
    start = time.perf_counter()
    if warm_from is not None:
        sets = sets + [f"transient.start_from={str(Path(warm_from).resolve())!r}"]
    tr = run_case(case, sets, out, quiet=True)["results"]["transient"]
    wall = time.perf_counter() - start
    m = tr["statistics"]["motor"]
    steady = tr.get("steady_state", {})
    row = {"load_torque_N_m": m["load_torque_N_m"], "speed_rpm": m["speed_rpm"],
           "speed_rad_per_s": m["speed_rad_per_s"], "friction_torque_N_m": m["friction_torque_N_m"],
           "output_power_W": m["output_power_W"], "electrical_power_W": m["electrical_power_W"],
           "efficiency": m["efficiency"], "normal_force_N": m["normal_force_N"],
           "coulomb_torque_bound_N_m": m["coulomb_torque_bound_N_m"],
           "energy_balance_relative": m["energy_balance_relative"], "steady": bool(steady.get("steady")),
           "periods": steady.get("cycles"), "steps": tr["steps"], "cutbacks": tr.get("cutbacks", 0), "wall_s": wall,
           "warm_from": Path(warm_from).name if warm_from is not None else ""}
    row.update(m["fractions"])
    return row


def speed_torque_plot(path: Path, curves: dict, title: str) -> None:
    """Speed [rpm] and efficiency [%] against load torque [mN m], one line per preload."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (speed_ax, eff_ax) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for label, c in curves.items():
        torque_mNm = [1e3 * x for x in c["torque_N_m"]]
        speed_ax.plot(torque_mNm, c["speed_rpm"], "o-", label=label)
        eff_ax.plot(torque_mNm, [100 * e for e in c["efficiency"]], "o-", label=label)
    speed_ax.set(xlabel="load torque [mN m]", ylabel="rotor speed [rpm]")
    eff_ax.set(xlabel="load torque [mN m]", ylabel="efficiency [%]")
    for ax in (speed_ax, eff_ax):
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/motor_curves")
    parser.add_argument("--case", type=Path, default=CASE,
                        help="the motor case (default: the shipped one; bench/cases/wwusm-motor-pinned.toml: the "
                             "stator of issue 11's curves)")
    parser.add_argument("--points", type=int, default=8, help="free-rotor load points per preload (besides stall)")
    parser.add_argument("--fe-step-s", type=float, default=None, help="FE-tier wall time per step of this case")
    parser.add_argument("--preloads", nargs="*", type=float, default=list(PRELOADS_N), metavar="N",
                        help="axial preloads [N] (default: the paper's two)")
    parser.add_argument("--set", nargs="*", default=[], help="further --set overrides for every point")
    parser.add_argument("--chain", choices=("up", "down"), default=None,
                        help="warm starts: each load point from the previous one's end state, from the held rotor "
                             "down, or from the no-load point up (default: every point from the case's start)")
    parser.add_argument("--grid-stall-N-m", nargs="*", type=float, default=None, metavar="T",
                        help="per preload, the held torque [N m] the load grid k / points x T is taken from (default: "
                             "this run's held rotor): a published curve's own, to rerun it at its loads")
    args = parser.parse_args()
    if args.grid_stall_N_m is not None and len(args.grid_stall_N_m) != len(args.preloads):
        parser.error("--grid-stall-N-m: give one torque per preload")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    start = time.perf_counter()
    for i, preload in enumerate(args.preloads):
        base = [f"transient.bodies[0].applied_force_N=[0.0, 0.0, {-preload!r}]"] + args.set
        stall = point(out / f"P{preload}_stall", base + ['transient.bodies[0].rotations[0].motion="fixed"'],
                      case=args.case)
        stall_torque = stall["friction_torque_N_m"]
        stall.update(preload_N=preload, load_torque_N_m=stall_torque)
        print(f"P = {preload} N: stall torque {stall_torque * 1e3:.4g} mN m ({stall['wall_s']:.0f} s)", flush=True)
        previous = out / f"P{preload}_stall" if args.chain == "down" else None
        for k in (reversed(range(args.points)) if args.chain == "down" else range(args.points)):
            load = (stall_torque if args.grid_stall_N_m is None else args.grid_stall_N_m[i]) * k / args.points
            sets = base + [f"transient.bodies[0].rotations[0].torque_N_m={-load!r}"]
            row = point(out / f"P{preload}_T{k}", sets, previous, args.case)
            if args.chain is not None:
                previous = out / f"P{preload}_T{k}"
            row["preload_N"] = preload
            rows.append(row)
            print(f"  load {load * 1e3:7.3f} mN m: {row['speed_rpm']:7.2f} rpm, efficiency "
                  f"{100 * row['efficiency']:5.2f} %, balance {row['energy_balance_relative']:.1e}, "
                  f"steady {row['steady']}, {row['wall_s']:.0f} s", flush=True)
        rows.append(stall)
    total = time.perf_counter() - start
    with open(out / "motor_curves.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row[k] for k in COLUMNS})
    curves = {}
    for preload in args.preloads:
        mine = sorted((r for r in rows if r["preload_N"] == preload), key=lambda r: r["load_torque_N_m"])
        curves[f"preload {preload} N"] = {key: [r[key] for r in mine] for key in
                                          ("load_torque_N_m", "speed_rpm", "output_power_W", "efficiency")}
        curves[f"preload {preload} N"]["torque_N_m"] = curves[f"preload {preload} N"].pop("load_torque_N_m")
    from app.runner import load_for_run

    case = load_for_run(args.case, args.set)
    vpp = 2 * max(e.amplitude_V or 0.0 for e in case.electrodes.values())
    speed_torque_plot(out / "motor_speed_torque.png", curves, f"WW-USM, modal tier: speed-torque at {vpp:.4g} Vpp, "
                                                f"{case.transient.drive.frequency_Hz / 1e3:.5g} kHz")
    steps = sum(r["steps"] for r in rows)
    report = {"points": len(rows), "wall_s": total, "steps": steps, "cutbacks": sum(r["cutbacks"] for r in rows),
              "periods": sum(r["periods"] or 0 for r in rows), "chain": args.chain}
    if args.fe_step_s:
        report["fe_tier_estimate_s"] = steps * args.fe_step_s
        report["ratio"] = report["fe_tier_estimate_s"] / total
    (out / "motor_curves.json").write_text(json.dumps({"report": report, "rows": rows}, indent=1))
    print(json.dumps(report, indent=1))
    print("| preload [N] | load [mN m] | speed [rpm] | output [mW] | electrical [mW] | efficiency [%] | "
          "sep / stick / fwd / bwd | balance | periods | wall [s] | from |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['preload_N']} | {r['load_torque_N_m'] * 1e3:.3f} | {r['speed_rpm']:.2f} | "
              f"{r['output_power_W'] * 1e3:.3f} | {r['electrical_power_W'] * 1e3:.1f} | {100 * r['efficiency']:.2f} | "
              f"{r['separation']:.2f} / {r['stick']:.2f} / {r['forward_slip']:.2f} / {r['backward_slip']:.2f} | "
              f"{r['energy_balance_relative']:.1e} | {r['periods']} | {r['wall_s']:.1f} | "
              f"{r['warm_from'] or 'start'} |")


if __name__ == "__main__":
    main()
