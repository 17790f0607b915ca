"""The modal tier's reduction choices against the FE tier, on the motor's coarse stator.

The motor case (cases/wwusm-motor.toml) on a coarse stator (the swept mesh's 6 mm, tip 2 mm sizes at the case's
mesh_refinement 0.6: 31 488 DOFs, fewer than the first stator's 40 556-DOF test mesh; both tiers locked to the same
FE F(1,4) pair), the rotor spun at a
prescribed 1.2 rad/s, from the harmonic start with the rotor seated, for 124 drive periods (the landing
transient: the rotor settles from its seat onto the wave). Each row varies one choice of the modal tier --
``reduction.interface_nodes`` (stator nodes kept as interface DOFs round the contact band),
``transient.contacts[0].sample_points`` (contact points sampling the band), ``reduction.cutoff_factor``
(fixed-interface modes kept up to this multiple of the drive frequency) -- and reports the cycle-mean friction
torque and normal force over periods 0-123 against the FE tier's run of the same case (``--fe DIR``: a finished
``piezodyn run`` directory of the FE tier, or none: the FE run is made here, about 5 000 steps). The defaults of
the case are chosen by this table (docs/reduced.md).

    .venv/bin/python bench/bench_motor_sampling.py --out /tmp/motor_sampling [--fe DIR] \\
        [--rows 'interface_nodes=64' 'interface_nodes=32' 'sample_points=128' 'cutoff_factor=6.0']

Prints one JSON line per row and a Markdown table; writes sampling.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASE = ROOT / "cases" / "wwusm-motor.toml"
COARSE = ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
          "geometry.parameters.mesh_refinement=0.6"]
SPIN = ['transient.bodies[0].rotations[0].motion="constant_rate"',
        "transient.bodies[0].rotations[0].rate_rad_per_s=1.2"]
PERIODS = 124
#: a row's key -> the case key it sets
ROW_KEYS = {"interface_nodes": "reduction.interface_nodes", "sample_points": "transient.contacts[0].sample_points",
            "cutoff_factor": "reduction.cutoff_factor", "enrich_modes": "reduction.enrich_modes"}
DEFAULT_ROWS = ["default", "interface_nodes=32", "interface_nodes=48", "sample_points=128", "sample_points=2048",
                "cutoff_factor=6.0", "enrich_modes=0"]


def cycle_means(h5_path: Path, frequency_Hz: float, periods: int) -> dict[str, np.ndarray]:
    """Per-period means of the contact's torque [N m] and normal force [N] (samples in (pT, (p+1)T])."""
    import h5py

    with h5py.File(h5_path, "r") as f:
        t = f["time_s"][:]
        torque = f["stator_rotor_torque_N_m"][:].reshape(len(t), -1)[:, 0]
        normal = f["stator_rotor_normal_force_N"][:].reshape(-1)
    period = 1.0 / frequency_Hz
    out = {"torque_N_m": [], "normal_force_N": []}
    for p in range(periods):
        rows = (t > p * period * (1 + 1e-9)) & (t <= (p + 1) * period * (1 + 1e-9))
        if rows.sum() < 2:
            break
        out["torque_N_m"].append(torque[rows].mean())
        out["normal_force_N"].append(normal[rows].mean())
    return {k: np.asarray(v) for k, v in out.items()}


def run(out: Path, tier: str, sets: list[str]) -> dict:
    """The run in ``out`` (made here, or a finished one found there)."""
    from app.runner import run_case

    end = PERIODS / 36065.0 * (1 + 1e-6)
    start = time.perf_counter()
    if (out / "summary.json").is_file():
        summary = json.loads((out / "summary.json").read_text())
        tr = summary["results"]["transient"]
        return {"wall_s": None, "steps": tr["steps"], "loop_s": tr["wall_time_s"],
                "frequency_Hz": tr["drive_frequency_Hz"], "series": out / tr["time_series"]}
    summary = run_case(CASE, COARSE + SPIN + [f'tier="{tier}"', f"transient.end_time_s={end!r}",
                                              "output.fields=false", "output.plots=false"] + sets, out, quiet=True)
    tr = summary["results"]["transient"]
    return {"wall_s": time.perf_counter() - start, "steps": tr["steps"], "loop_s": tr["wall_time_s"],
            "frequency_Hz": tr["drive_frequency_Hz"], "series": out / tr["time_series"]}


def main() -> None:
    from app.errors import CaseError

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/motor_sampling"))
    parser.add_argument("--fe", type=Path, default=None, help="a finished FE-tier run of the same case (its directory)")
    parser.add_argument("--rows", nargs="+", default=DEFAULT_ROWS,
                        help="'default' or KEY=VALUE with KEY one of " + ", ".join(ROW_KEYS))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.fe is None:
        args.fe = args.out / "fe"
        fe = run(args.fe, "fe", [])
        print(f"FE tier: {fe['steps']} steps in {fe['wall_s']:.0f} s", file=sys.stderr, flush=True)
    fe_summary = json.loads((args.fe / "summary.json").read_text())
    frequency = fe_summary["results"]["transient"]["drive_frequency_Hz"]      # the drive as run (locked)
    reference = cycle_means(args.fe / fe_summary["results"]["transient"]["time_series"], frequency, PERIODS)
    periods = len(reference["torque_N_m"])
    ref = {k: float(v.mean()) for k, v in reference.items()}
    rows = []
    for spec in args.rows:
        sets = []
        if spec != "default":
            key, _, value = spec.partition("=")
            if key not in ROW_KEYS:
                parser.error(f"--rows {spec}: {key} is not one of {', '.join(ROW_KEYS)}")
            sets = [f"{ROW_KEYS[key]}={value}"]
        name = spec.replace("=", "_")
        try:
            r = run(args.out / name, "modal", sets)
        except CaseError as exc:        # e.g. more interface nodes than the coarse band has
            rows.append({"row": spec, "refused": str(exc)})
            print(json.dumps(rows[-1]), flush=True)
            continue
        means = cycle_means(r["series"], r["frequency_Hz"], periods)
        n = min(periods, len(means["torque_N_m"]))
        row = {"row": spec, "periods": n, "steps": r["steps"], "wall_s": r["wall_s"],
               "ms_per_step": 1e3 * r["loop_s"] / r["steps"]}
        for key, values in means.items():
            value = float(values[:n].mean())
            row[key] = value
            row[key + "_vs_fe"] = value / float(reference[key][:n].mean()) - 1
        rows.append(row)
        print(json.dumps(row), flush=True)
    (args.out / "sampling.json").write_text(json.dumps({"fe": {**ref, "periods": periods}, "rows": rows}, indent=1))
    print(f"FE tier over periods 0-{periods - 1}: torque {ref['torque_N_m'] * 1e3:.3f} mN m, "
          f"N {ref['normal_force_N']:.4f} N")
    print("| modal tier | torque [mN m] | vs FE | N [N] | vs FE | ms/step |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if "refused" in r:
            print(f"| {r['row']} | refused: {r['refused'].split(': ', 2)[-1]} | | | | |")
            continue
        print(f"| {r['row']} | {r['torque_N_m'] * 1e3:.3f} | {100 * r['torque_N_m_vs_fe']:+.2f} % | "
              f"{r['normal_force_N']:.4f} | {100 * r['normal_force_N_vs_fe']:+.2f} % | {r['ms_per_step']:.2f} |")
    assert all(math.isfinite(r["torque_N_m"]) for r in rows if "refused" not in r)


if __name__ == "__main__":
    main()
