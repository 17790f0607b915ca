"""The motor's three tiers at the same loads: speed, torque and cost per point (FE, modal, lumped).

The FE and modal points are result directories of `piezodyn run` (their summary.json: the tier, the load, the
steady point's means over the last window, the cost); the lumped tier (the F(1,4) pair's modal data and the
friction-drive law, docs/lumped-motor.md) is solved here, in this process, at every load those runs carry, on each
of its branches, and timed (best of ``--repeat`` solves). A held rotor's load is its stall torque; the lumped
tier's stall is the law's μ N r_c. Each point's error is taken against the FE point at that load where one
exists, else against the modal tier's.

    .venv/bin/python bench/bench_motor_tiers.py --lumped-case cases/wwusm-motor-lumped.toml \
        --runs /work/runs/fe26/point RUN_DIR ... [--csv docs/figures/motor_tiers.csv] [--no-lumped]

The cost of a point: the loop's wall time per simulated ms times the simulated time (a run killed and resumed
reports the rate of its last part, applied to the whole), and the set-up (mesh, reduced stator or cache read,
compilation) beside it.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_lumped_motor import lumped_at  # noqa: E402

from app.case.schema import load_case  # noqa: E402
from app.intervals import half_width_95  # noqa: E402
from app.lumped import friction_drive as fd  # noqa: E402

COLUMNS = ["tier", "load_mN_m", "held", "speed_rpm", "torque_mN_m", "normal_force_N", "wave_normal_um",
           "speed_error_pct", "torque_error_pct", "reference", "periods", "steady", "half_mean", "half_min",
           "half_max", "half_ci95", "output_power_mW", "electrical_power_mW", "efficiency_pct", "loop_wall_s",
           "setup_wall_s", "run"]


def run_point(directory: Path) -> dict:
    """One FE or modal run's steady point and cost (summary.json of ``directory``)."""
    summary = json.loads((directory / "summary.json").read_text())
    tr = summary["results"]["transient"]
    motor = tr["statistics"]["motor"]
    rotation = summary["case"]["transient"]["bodies"][0]["rotations"][0]
    held = rotation["motion"] == "fixed"
    steady = tr.get("steady_state") or {}
    half = _last_half(steady) if not steady.get("steady") else (None, None, None, None)
    return {
        "tier": summary["case"]["tier"], "held": held,
        "load_mN_m": 1e3 * (motor["friction_torque_N_m"] if held else motor["load_torque_N_m"]),
        "speed_rpm": motor["speed_rpm"], "torque_mN_m": 1e3 * motor["friction_torque_N_m"],
        "normal_force_N": motor["normal_force_N"],
        "wave_normal_um": 1e6 * motor["contact_point_amplitude_m"]["normal"],
        "output_power_mW": 1e3 * motor["output_power_W"], "electrical_power_mW": 1e3 * motor["electrical_power_W"],
        "efficiency_pct": 100.0 * motor["efficiency"],
        "periods": steady.get("cycles"), "steady": bool(steady.get("steady")),
        "half_mean": half[0], "half_min": half[1], "half_max": half[2], "half_ci95": half[3],
        "loop_wall_s": tr["wall_s_per_simulated_ms"] * tr["simulated_time_s"] * 1e3,
        "setup_wall_s": tr["setup_wall_s"], "run": str(directory),
    }


#: batches of the last half for the mean's interval
BATCHES = 8


def _last_half(steady: dict) -> tuple:
    """(mean, least, largest, 95 % half-width of the mean) over the run's last half of the period means of the
    watched quantity (a free rotor's speed [rpm], a held rotor's torque [mN m]): the level of a point that wanders
    (the window rule not met; not reported for a steady point, whose last half may hold its approach). The interval
    is from batch means (BATCHES consecutive batches, app/intervals.py), since consecutive periods are correlated."""
    means = steady.get("cycle_means") or []
    scale = {"speed": 60.0 / (2.0 * math.pi), "torque": 1e3}.get(steady.get("watched"))
    if scale is None or len(means) < 2 * BATCHES:
        return None, None, None, None
    half = [v * scale for v in means[len(means) // 2:]]
    size = len(half) // BATCHES
    batch = [sum(half[i * size:(i + 1) * size]) / size for i in range(BATCHES)]
    return sum(half) / len(half), min(half), max(half), half_width_95(batch)


def lumped_points(section, load_mN_m: float, held: bool, repeat: int) -> list[dict]:
    """The lumped tier's roots at one load (held: the stall), each as a row."""
    points, wall = lumped_at(section, None if held else load_mN_m * 1e-3, repeat)
    p = fd.derive_parameters(section)
    rows = []
    for point in points:
        torque = p.mu * p.normal_force_N * p.radius_m if held else load_mN_m * 1e-3
        rows.append({"tier": "lumped", "held": held, "load_mN_m": torque * 1e3 if held else load_mN_m,
                     "speed_rpm": point["speed_rpm"], "torque_mN_m": torque * 1e3,
                     "normal_force_N": p.normal_force_N, "wave_normal_um": point["wave_amplitude_m"] * 1e6,
                     "output_power_mW": 1e3 * point["output_power_W"],
                     "electrical_power_mW": 1e3 * point["electrical_power_W"],
                     "efficiency_pct": 100.0 * point["efficiency"], "periods": None, "steady": True,
                     "half_mean": None, "half_min": None,
                     "half_max": None, "half_ci95": None, "loop_wall_s": wall, "setup_wall_s": 0.0,
                     "run": "lumped (this process)"})
    return rows


def with_errors(rows: list[dict], baselines: list[dict] = ()) -> list[dict]:
    """Each row's error against the FE row at its load, else the modal row: the speed of a free point, the torque
    of a held one (a point that did not settle by its last-half mean). With ``baselines`` (a
    convergence study): against the baseline run of the same kind (free or held) instead."""
    def reference(row):
        if baselines:
            return next((b for b in baselines if b["held"] == row["held"] and b["run"] != row["run"]), None)
        for tier in ("fe", "modal"):
            for other in rows:
                if other["tier"] == tier and other is not row and other["held"] == row["held"] and (
                        row["held"] or abs(other["load_mN_m"] - row["load_mN_m"]) <= 1e-6):
                    return other
        return None

    for row in rows:
        ref = reference(row) if row["tier"] != "fe" or baselines else None
        row["reference"] = (Path(ref["run"]).name if baselines else ref["tier"]) if ref else ""
        row["speed_error_pct"] = (100.0 * (_level(row, "speed_rpm") / _level(ref, "speed_rpm") - 1.0)
                                  if ref and not row["held"] else None)
        # a free point's torque is its load in every tier (steady state); the held rotor's is the stall torque
        row["torque_error_pct"] = (100.0 * (_level(row, "torque_mN_m") / _level(ref, "torque_mN_m") - 1.0)
                                   if ref and row["held"] else None)
    return rows


def _level(row: dict, key: str) -> float:
    """A row's value for a comparison: its last window's mean, or over its last half where it did not settle."""
    return row["half_mean"] if row["half_mean"] is not None else row[key]


def fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="+", required=True, help="FE and modal result directories (summary.json)")
    ap.add_argument("--lumped-case", default=str(ROOT / "cases" / "wwusm-motor-lumped.toml"))
    ap.add_argument("--repeat", type=int, default=3, help="lumped solves per load; the best is reported")
    ap.add_argument("--csv", help="write the table here as well")
    ap.add_argument("--no-lumped", action="store_true",
                    help="only the runs' rows (a table of modal or FE points, e.g. a convergence study)")
    ap.add_argument("--baselines", nargs="*", default=[],
                    help="runs (a free and a held one) every other run of its kind is compared with, in the runs' "
                         "order instead of sorted by load")
    args = ap.parse_args()
    runs = [run_point(Path(d)) for d in args.runs]
    section = load_case(args.lumped_case).lumped
    loads = sorted({(round(r["load_mN_m"], 6), r["held"]) for r in runs if not r["held"]}) + [(None, True)]
    lumped = []
    for load, held in ([] if args.no_lumped else loads):
        lumped += lumped_points(section, load or 0.0, held, args.repeat)
    order = {"fe": 0, "modal": 1, "lumped": 2}
    baselines = [run_point(Path(d)) for d in args.baselines]
    if baselines:
        rows = with_errors(baselines + [r for r in runs + lumped if r["run"] not in {b["run"] for b in baselines}],
                           baselines)
    else:
        rows = with_errors(sorted(runs + lumped, key=lambda r: (
            r["held"], round(r["load_mN_m"] if not r["held"] else 0, 6), order[r["tier"]])))
    print("| run | tier | load [mN m] | speed [rpm] | last half: mean ± 95 % (range) [rpm; held: mN m] | "
          "torque [mN m] | N [N] | wave [µm] | out / drawn [mW] | efficiency | speed error | torque error | "
          "periods (steady) | loop wall [s] | set-up [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    def err(r, k):
        return "-" if r[k] is None else f"{r[k]:+.1f} % ({r['reference']})"

    for r in rows:
        half = ("-" if r["half_mean"] is None else
                f"{r['half_mean']:.2f} ± {r['half_ci95']:.2f} ({r['half_min']:.2f}–{r['half_max']:.2f})")
        periods = "-" if r["periods"] is None else f"{r['periods']} ({'yes' if r['steady'] else 'no'})"
        load = "held" if r["held"] else fmt(r["load_mN_m"], ".3f")
        print(f"| {Path(r['run']).name} | {r['tier']} | {load} | {r['speed_rpm']:.2f} | {half} | "
              f"{r['torque_mN_m']:.3f} | {r['normal_force_N']:.3f} | {r['wave_normal_um']:.3f} | "
              f"{r['output_power_mW']:.1f} / {r['electrical_power_mW']:.1f} | {r['efficiency_pct']:.1f} % | "
              f"{err(r, 'speed_error_pct')} | {err(r, 'torque_error_pct')} | {periods} | "
              f"{r['loop_wall_s']:.4g} | {r['setup_wall_s']:.4g} |")
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS)
            writer.writeheader()
            writer.writerows({k: r.get(k) for k in COLUMNS} for r in rows)
        print(f"table: {args.csv}")


if __name__ == "__main__":
    main()
