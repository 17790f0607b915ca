"""The motor's speed-torque points on two meshes of the stator, same drive definition and same start (issue 24).

For each load torque, the shipped motor case (the drive locked to each mesh's own F(1,4)) runs on every mesh
(``geometry.parameters.mesh_refinement``) from the harmonic start with the rotor seated and already spinning at a
stated speed (``rate_rad_per_s`` of the free rotation: the branch the point is to follow; at 0.98 N the motor is
bistable, and a rotor spun up from rest on one mesh may settle in the other branch than on another, so the branch
is chosen by the start, not left to the spin-up), until the case's steady-state test after ``--min-periods``.
Prints each point's speed on each mesh and the differences relative to the first mesh's no-load speed; writes
mesh_points.csv.

    .venv/bin/python bench/bench_motor_mesh.py --out DIR --preload 0.98 --refinements 0.6 1.0 \\
        --loads-mN-m 0 9.542 19.084 28.626 --start-rpm 1865 [--min-periods 400] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.runner import run_case  # noqa: E402

CASE = ROOT / "cases" / "wwusm-motor.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/motor_mesh"))
    parser.add_argument("--preload", type=float, default=0.98, help="axial preload [N]")
    parser.add_argument("--refinements", nargs="+", type=float, default=[0.6, 1.0])
    parser.add_argument("--loads-mN-m", nargs="+", type=float, required=True)
    parser.add_argument("--start-rpm", nargs="+", type=float, required=True,
                        help="the rotor's initial speed per load (one value: the same for every load)")
    parser.add_argument("--min-periods", type=int, default=400)
    parser.add_argument("--set", nargs="*", default=[])
    args = parser.parse_args()
    starts = args.start_rpm * len(args.loads_mN_m) if len(args.start_rpm) == 1 else args.start_rpm
    if len(starts) != len(args.loads_mN_m):
        parser.error("--start-rpm: one value, or one per load")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for load, start_rpm in zip(args.loads_mN_m, starts):
        for refinement in args.refinements:
            sets = [f"geometry.parameters.mesh_refinement={refinement!r}",
                    f"transient.bodies[0].applied_force_N=[0.0, 0.0, {-args.preload!r}]",
                    f"transient.bodies[0].rotations[0].torque_N_m={-load * 1e-3!r}",
                    f"transient.bodies[0].rotations[0].rate_rad_per_s={start_rpm * 2 * math.pi / 60!r}",
                    f"transient.steady_state.min_cycles={args.min_periods}", "output.plots=false"] + args.set
            clock = time.perf_counter()
            tr = run_case(CASE, sets, args.out / f"r{refinement}_T{load:g}", quiet=True)["results"]["transient"]
            m = tr["statistics"]["motor"]
            row = {"refinement": refinement, "fe_dofs": tr["reduction"]["fe_dofs"], "load_mN_m": load,
                   "start_rpm": start_rpm, "speed_rpm": m["speed_rpm"],
                   "friction_torque_mN_m": 1e3 * m["friction_torque_N_m"], "normal_force_N": m["normal_force_N"],
                   "electrical_power_W": m["electrical_power_W"], "resonance_Hz": tr["drive"]["resonance_Hz"],
                   "steady": bool(tr.get("steady_state", {}).get("steady")),
                   "periods": tr.get("steady_state", {}).get("cycles"), "wall_s": time.perf_counter() - clock}
            rows.append(row)
            print(f"refinement {refinement}: {row['fe_dofs']} DOFs, load {load:.3f} mN m: {row['speed_rpm']:.2f} rpm "
                  f"(steady {row['steady']}, {row['periods']} periods, {row['wall_s']:.0f} s)", flush=True)
    with open(args.out / "mesh_points.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    base = args.refinements[0]
    no_load = next(r["speed_rpm"] for r in rows if r["refinement"] == base and r["load_mN_m"] == min(args.loads_mN_m))
    print("| load [mN m] | " + " | ".join(f"r = {r:g} [rpm]" for r in args.refinements)
          + " | difference (of the first mesh's no-load speed) |")
    print("|---|" + "---|" * len(args.refinements) + "---|")
    for load in args.loads_mN_m:
        speeds = [next(r["speed_rpm"] for r in rows if r["refinement"] == ref and r["load_mN_m"] == load)
                  for ref in args.refinements]
        print(f"| {load:.3f} | " + " | ".join(f"{s:.2f}" for s in speeds)
              + f" | {100 * (speeds[-1] - speeds[0]) / no_load:+.2f} % |")


if __name__ == "__main__":
    main()
