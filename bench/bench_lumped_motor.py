"""The lumped motor (cases/wwusm-motor-lumped.toml) against the modal tier's measured speed-torque points.

The modal points are BENCHMARKS.md's "Motor speed-torque in the modal tier" (2026-11-23, the pinned stator of
bench/cases/wwusm-motor-pinned.toml, 0.98 N, from rest, chained up from no load, >= 500 periods each); the lumped
tier is solved here at the same loads, on both branches, and timed (whole ``solve`` per load, best of
``--repeat``). ``--modal DIR ...``: modal runs of this session (their summary.json) whose operating point and wall
time are put beside it (the "faster" claim needs both sides in one session).

    .venv/bin/python bench/bench_lumped_motor.py [--case cases/wwusm-motor-lumped.toml] [--modal DIR ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

from app.case.schema import load_case
from app.lumped import friction_drive as fd

#: BENCHMARKS.md, "Motor speed-torque in the modal tier", 0.98 N: (load [mN m], speed [rpm], electrical [mW],
#: efficiency [%]); the held rotor's load is its stall torque. The 0.98 N curve: 9 points, 335 s.
MODAL_098 = [(0.000, 50.48, 143.2, 0.00), (3.232, 49.18, 153.9, 10.81), (6.464, 43.04, 147.9, 19.71),
             (9.696, 40.92, 155.7, 26.70), (12.929, 38.61, 161.5, 32.37), (16.161, 36.29, 166.4, 36.90),
             (19.393, 33.67, 169.0, 40.47), (22.625, 30.32, 167.5, 42.89), (25.857, 0.00, 98.6, 0.00)]
MODAL_098_CURVE_WALL_S = 335.0


def lumped_at(section, load_N_m: float | None, repeat: int) -> tuple[list[dict], float]:
    """Every root at ``load_N_m`` (None: held) and the best wall time of ``repeat`` solves [s]."""
    p = fd.derive_parameters(section)
    bound = p.mu * p.normal_force_N * p.radius_m
    ratio = None if load_N_m is None else load_N_m / bound
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        found = fd.roots(p, ratio)
        points = [fd.operating_point(p, r, 0.0 if load_N_m is None else load_N_m) for r in found]
        best = min(best, time.perf_counter() - start)
    return points, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="cases/wwusm-motor-lumped.toml")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--modal", nargs="*", default=[], help="modal-tier result directories of this session")
    args = ap.parse_args()
    case = load_case(args.case)
    section = case.lumped
    p = fd.derive_parameters(section)
    print(f"lumped: free wave {fd.free_amplitude(p) * 1e6:.3f} um, N / F_m {p.normal_force_N / p.drive_force_N:.3f}, "
          f"mu N r_c {p.mu * p.normal_force_N * p.radius_m * 1e3:.3f} mN m")
    print("| load [mN m] | modal speed [rpm] | modal P_el [mW] | lumped speed, upper / lower [rpm] | "
          "lumped P_el, upper / lower [mW] | lumped wave, upper / lower [um] | roots | lumped wall [ms] |")
    print("|---|---|---|---|---|---|---|---|")
    walls = []
    for load, speed, p_el, _ in MODAL_098:
        held = speed == 0.0
        points, wall = lumped_at(section, None if held else load * 1e-3, args.repeat)
        walls.append(wall)
        upper, lower = (points[0], points[-1]) if len(points) > 1 else (points[0] if points else None, None)

        def cell(point, key, scale, fmt):
            return "-" if point is None else format(point[key] * scale, fmt)

        print(f"| {load:.3f}{' (held)' if held else ''} | {speed:.2f} | {p_el:.1f} | "
              f"{cell(upper, 'speed_rpm', 1, '.2f')} / {cell(lower, 'speed_rpm', 1, '.2f')} | "
              f"{cell(upper, 'electrical_power_W', 1e3, '.1f')} / {cell(lower, 'electrical_power_W', 1e3, '.2f')} | "
              f"{cell(upper, 'wave_amplitude_m', 1e6, '.3f')} / {cell(lower, 'wave_amplitude_m', 1e6, '.4f')} | "
              f"{len(points)} | {wall * 1e3:.1f} |")
    held_lumped = p.mu * p.normal_force_N * p.radius_m
    print(f"stall: modal {MODAL_098[-1][0]:.3f} mN m (held, seated), lumped mu N r_c {held_lumped * 1e3:.3f} mN m "
          f"({(MODAL_098[-1][0] * 1e-3 / held_lumped - 1) * 100:+.1f} % modal against lumped)")
    per_point = sum(walls) / len(walls)
    print(f"lumped wall per point: {per_point * 1e3:.1f} ms (mean of {len(walls)} loads, best of {args.repeat}); "
          f"modal (BENCHMARKS 2026-11-23): {MODAL_098_CURVE_WALL_S / len(MODAL_098):.1f} s per point "
          f"-> {MODAL_098_CURVE_WALL_S / len(MODAL_098) / per_point:.0f} x")
    start = time.perf_counter()
    whole = fd.solve(dataclasses.replace(section))
    print(f"whole case (operating point + {section.curve_points}-point curve, both branches): "
          f"{(time.perf_counter() - start) * 1e3:.0f} ms, {whole['points_solved']} root scans")
    for directory in args.modal:
        summary = json.loads((Path(directory) / "summary.json").read_text())
        tr = summary["results"]["transient"]
        motor = tr["statistics"]["motor"]
        points, wall = lumped_at(section, motor["load_torque_N_m"] or 0.0, args.repeat)
        print(f"modal run {directory}: load {motor['load_torque_N_m'] * 1e3:.3f} mN m, {motor['speed_rpm']:.2f} rpm, "
              f"P_el {motor['electrical_power_W'] * 1e3:.1f} mW, {tr['steps']} steps, "
              f"loop wall {tr['wall_time_s']:.1f} s "
              f"(+ setup {tr['setup_wall_s']:.1f} s); lumped at that load {wall * 1e3:.1f} ms: "
              f"{(tr['wall_time_s'] + tr['setup_wall_s']) / wall:.0f} x")


if __name__ == "__main__":
    main()
