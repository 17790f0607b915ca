"""The motor's chain of controlled runs (issue 25, docs/motor-chain.md): from a prescribed rigid travelling wave on
the contact face to the full modal model, one effect added per run, at no load and with the rotor held, on one
geometry and mesh; each run against the friction-drive law evaluated with its own wave, N and μ.

The steps are model surgery on the case's reduced stator (app/reduced/surgery.py, the case keys
``reduction.surgery``, ``reduction.site_motion``, ``reduction.wave_scale``):

1. ``travelling``: the F(1,4) pair's free wave at the contact sites reduced to its travelling component (uniform
   amplitude, order 4, one direction), normal and circumferential only (``site_motion = "planar"``), prescribed
   (a rigid stator surface) with its normal amplitude the full model's at that operating point: the law's case;
2. ``own wave``: the pair's own wave at the sites (its standing part and the ring's non-uniformity), still planar
   and prescribed;
3. ``meridional``: + the sites' meridional motion (the full site rows);
4. ``elastic pair``: + an elastic stator of one mode pair (the F(1,4) pair free, driven by the electrodes and loaded
   by the contact; the electrodes' static response of the other modes kept): the wave is no longer prescribed;
5. ``full``: + the full reduced basis (the other modes' compliance at the contact: local, tangential) = the model.

The swap: ``elastic pair, planar`` takes step 4 before step 3 (2 -> 4' -> 4), to show how much the order matters.
Every run starts as the case does (harmonic start, rotor seated and at rest) and runs to the same end; the held
rotor is ``motion = "fixed"``. The rigid steps' ``wave_scale`` comes from the full run's wave at the same operating
point (mean over the sites of the normal displacement's first harmonic, the per-site tables) over the wave the
surgery prescribes at scale 1 (``results.transient.surgery.site_wave_m``, from a run of two periods).

The law (app/references/friction_drive.py) with the run's own W (its sites' normal wave), U_t (the prescribed
circumferential amplitude for a rigid wave, else the contact probe's circumferential amplitude), the penalty as
the Winkler stiffness, the band's slant width as the depth, N (the run's mean normal force), the wave's order
round the contact circle r_c, and μ = μ_d (1 + (FACT - 1) exp(-DC |s|)) = μ_s at DC = 0: the contact
half-angle θ_c from N, then the no-load deficit 1 - V_0 / (ω U_t) and stall / (μ N r_c) = 1.

    .venv/bin/python bench/bench_motor_chain.py --out DIR [--case cases/wwusm-motor.toml] \
        [--set KEY=VALUE ...] [--free-ms 60 --free-min-periods 2000 --held-ms 30 --held-min-periods 1000]

writes DIR/chain.csv and DIR/chain.md (one row per run) and keeps every run's directory (a run whose directory
holds a summary of the same settings is read, not run again). The docs' table: the coarse stator of the tests
(``--set geometry.parameters.mesh_size_m=0.006 --set geometry.parameters.tip_mesh_size_m=0.002 --set
reduction.interface_nodes=32 --set output.fields=false --set output.plots=false``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.references import friction_drive as law  # noqa: E402

HELD = 'transient.bodies[0].rotations[0].motion="fixed"'
#: (name, what it adds, surgery, site motion, the run it changes)
STEPS = [
    ("travelling", "prescribed travelling wave, normal + circumferential (the law's case)", "travelling_wave",
     "planar", None),
    ("own_wave", "+ the pair's own wave shape round the ring (standing part, non-uniformity)", "rigid_wave",
     "planar", "travelling"),
    ("meridional", "+ meridional motion of the sites", "rigid_wave", "full", "own_wave"),
    ("elastic_pair", "+ elastic stator: the F(1,4) pair free, loaded by the contact", "modal_pair", "full",
     "meridional"),
    ("full", "+ the full reduced basis (the other modes' compliance) = the full model", "none", "full",
     "elastic_pair"),
    ("elastic_pair_planar", "swap: + elastic pair before the meridional motion", "modal_pair", "planar", "own_wave"),
]
COLUMNS = ["step", "adds", "point", "surgery", "site_motion", "wave_scale", "speed_rpm", "torque_mN_m",
           "normal_force_N", "wave_normal_um", "wave_circumferential_um", "wave_meridional_um", "separation",
           "theta_c_rad", "deficit", "deficit_law", "deficit_vs_law_pct", "stall_ratio", "stall_vs_law_pct",
           "speed_change_pct", "torque_change_pct", "from_step", "periods", "steady", "loop_wall_s", "run"]


def run(out: Path, name: str, case: Path, sets: list[str]) -> dict:
    """The run's summary (run now unless ``out/name`` holds one of the same settings)."""
    from app.runner import run_case

    directory = out / name
    record = directory / "chain_settings.json"
    if (directory / "summary.json").is_file() and record.is_file() and json.loads(record.read_text()) == sets:
        return json.loads((directory / "summary.json").read_text())
    print(f"chain: {name}: {' '.join(sets)}", flush=True)
    summary = run_case(case, sets, directory, quiet=True)
    record.write_text(json.dumps(sets))
    return json.loads((directory / "summary.json").read_text()) if summary is None else \
        json.loads((directory / "summary.json").read_text())


def site_wave(directory: Path, contact: str = "stator_rotor", rows: int = 20) -> float:
    """Mean over the sites of the normal displacement's first-harmonic amplitude [m], last ``rows`` intervals."""
    import h5py

    with h5py.File(directory / "transient.h5", "r") as f:
        c = f[f"{contact}_sites_normal_displacement_cos"][-rows:]
        s = f[f"{contact}_sites_normal_displacement_sin"][-rows:]
    return float(np.hypot(c, s).mean())


def law_values(summary: dict, W: float, U: float) -> dict:
    """θ_c, the law's deficit and its μ for the run's own N and wave."""
    case = summary["case"]
    contact = case["transient"]["contacts"][0]
    tr = summary["results"]["transient"]
    motor = tr["statistics"]["motor"]
    r_c = motor["contact_radius_m"]
    area = (tr["reduction"].get("band_area_m2") or [None])[0]
    friction = contact["friction"]
    mu = friction["mu_dynamic"] * friction["static_ratio"] if friction.get("decay_s_per_m", 0.0) == 0.0 else \
        friction["mu_dynamic"]
    order = 4
    depth = area / (2 * math.pi * r_c) if area else None
    out = {"mu": mu, "r_c": r_c}
    if depth and W > 0:
        per_wavelength = motor["normal_force_N"] / order / depth
        theta = law.contact_half_angle(per_wavelength, contact["stiffness"], W, order / r_c)
        out["theta_c"] = theta
        out["deficit_law"] = 1.0 - law.no_load_speed(1.0, theta)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--case", type=Path, default=ROOT / "cases" / "wwusm-motor.toml")
    parser.add_argument("--set", action="append", default=[], dest="sets")
    parser.add_argument("--free-ms", type=float, default=60.0)
    parser.add_argument("--free-min-periods", type=int, default=2000)
    parser.add_argument("--held-ms", type=float, default=30.0)
    parser.add_argument("--held-min-periods", type=int, default=1000)
    parser.add_argument("--band-area-m2", type=float, default=None,
                        help="the contact band's area (default: the run's, results.transient.reduction)")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    points = {"free": [f"transient.end_time_s={args.free_ms * 1e-3!r}",
                       f"transient.steady_state.min_cycles={args.free_min_periods}"],
              "held": [f"transient.end_time_s={args.held_ms * 1e-3!r}",
                       f"transient.steady_state.min_cycles={args.held_min_periods}", HELD]}
    base = list(args.sets) + ["output.contact_sites=true"]
    rows = []
    for point, point_sets in points.items():
        reference = run(out, f"full-{point}", args.case, base + point_sets)
        W_ref = site_wave(out / f"full-{point}")
        results = {}
        for name, _adds, surgery, motion, _ in STEPS:
            sets = base + point_sets + [f'reduction.surgery="{surgery}"', f'reduction.site_motion="{motion}"']
            scale = 1.0
            if surgery in ("rigid_wave", "travelling_wave"):
                # the prescribed wave at scale 1 (two periods suffice: the surgery's record)
                probe = run(out, f"{name}-probe", args.case, base + [f'reduction.surgery="{surgery}"',
                                                                     f'reduction.site_motion="{motion}"',
                                                                     "transient.end_time_s=6e-5",
                                                                     "transient.steady_state.min_cycles=1"])
                scale = W_ref / probe["results"]["transient"]["surgery"]["site_wave_m"]["normal_m"]
                sets.append(f"reduction.wave_scale={scale!r}")
            summary = reference if surgery == "none" else run(out, f"{name}-{point}", args.case, sets)
            directory = out / (f"full-{point}" if surgery == "none" else f"{name}-{point}")
            results[name] = (summary, directory, scale)
        for name, adds, surgery, motion, before in STEPS:
            summary, directory, scale = results[name]
            tr = summary["results"]["transient"]
            motor = tr["statistics"]["motor"]
            record = tr.get("surgery") or {}
            W = site_wave(directory)
            probe = motor.get("contact_point_amplitude_m", {})
            if surgery in ("rigid_wave", "travelling_wave"):
                U = record["site_wave_m"]["circumferential_m"]          # at the run's scale
            else:
                U = probe.get("tangential", float("nan"))
            if args.band_area_m2 is not None:
                tr["reduction"]["band_area_m2"] = [args.band_area_m2]
            lv = law_values(summary, W, U)
            omega = 2 * math.pi * tr["drive_frequency_Hz"]
            speed = motor["speed_rad_per_s"]
            deficit = 1.0 - speed * lv["r_c"] / (omega * U) if point == "free" else None
            stall = motor["friction_torque_N_m"] / (lv["mu"] * motor["normal_force_N"] * lv["r_c"]) \
                if point == "held" else None
            prev = results.get(before)
            change_speed = change_torque = None
            if prev is not None:
                pm = prev[0]["results"]["transient"]["statistics"]["motor"]
                if point == "free":
                    change_speed = 100.0 * (motor["speed_rpm"] / pm["speed_rpm"] - 1.0)
                else:
                    change_torque = 100.0 * (motor["friction_torque_N_m"] / pm["friction_torque_N_m"] - 1.0)
            steady = tr.get("steady_state") or {}
            rows.append({
                "step": name, "adds": adds, "point": point, "surgery": surgery, "site_motion": motion,
                "wave_scale": scale, "speed_rpm": motor["speed_rpm"], "torque_mN_m": 1e3 * motor["friction_torque_N_m"],
                "normal_force_N": motor["normal_force_N"], "wave_normal_um": 1e6 * W,
                "wave_circumferential_um": 1e6 * U, "wave_meridional_um": 1e6 * probe.get("meridional", float("nan")),
                "separation": (motor.get("fractions") or {}).get("separation"),
                "theta_c_rad": lv.get("theta_c"), "deficit": deficit,
                "deficit_law": lv.get("deficit_law") if point == "free" else None,
                "deficit_vs_law_pct": 100.0 * (deficit / lv["deficit_law"] - 1.0)
                if point == "free" and lv.get("deficit_law") else None,
                "stall_ratio": stall, "stall_vs_law_pct": 100.0 * (stall - 1.0) if stall is not None else None,
                "speed_change_pct": change_speed, "torque_change_pct": change_torque, "from_step": before,
                "periods": steady.get("cycles"), "steady": steady.get("steady"),
                "loop_wall_s": tr.get("stepping_wall_time_s"), "run": str(directory)})
    with open(out / "chain.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    (out / "chain.md").write_text(markdown(rows))
    print(markdown(rows))


def _f(value, fmt):
    return "—" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, fmt)


def markdown(rows: list[dict]) -> str:
    lines = ["| step | adds | point | speed [rpm] | torque [mN m] | N [N] | W [µm] | U_t [µm] | θ_c [rad] | "
             "deficit | law | vs law | stall/(μNr_c) | change |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        change = r["speed_change_pct"] if r["point"] == "free" else r["torque_change_pct"]
        lines.append(
            f"| {r['step']} | {r['adds']} | {r['point']} | {_f(r['speed_rpm'], '.2f')} | {_f(r['torque_mN_m'], '.3f')}"
            f" | {_f(r['normal_force_N'], '.3f')} | {_f(r['wave_normal_um'], '.3f')}"
            f" | {_f(r['wave_circumferential_um'], '.3f')} | {_f(r['theta_c_rad'], '.4f')}"
            f" | {_f(r['deficit'], '.5f')} | {_f(r['deficit_law'], '.5f')} | {_f(r['deficit_vs_law_pct'], '+.1f')} %"
            f" | {_f(r['stall_ratio'], '.4f')} | {_f(change, '+.2f')} % from {r['from_step'] or '—'} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
