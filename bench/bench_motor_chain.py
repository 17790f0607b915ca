"""The motor's chain of controlled runs (issue 25, docs/motor-chain.md): from a prescribed rigid travelling wave on
the contact face to the full modal model, one effect added per run, at no load and with the rotor held, on one
geometry and mesh; each run against the friction-drive law evaluated with its own wave, N and μ.

The steps are model surgery on the case's reduced stator (app/reduced/surgery.py, the case keys
``reduction.surgery``, ``reduction.site_motion``, ``reduction.wave_scale``):

1. ``travelling_law``: the F(1,4) pair's free wave at the contact sites reduced to its travelling component
   (uniform amplitude, order 4, one direction), normal and circumferential only (``site_motion = "planar"``),
   prescribed (a rigid stator surface) with its normal amplitude the full model's at that operating point; half
   the case's step and a tenth of its friction regularisation: the law's case;
2. ``travelling_reg``: + the case's friction regularisation (0.1 mm/s);
3. ``travelling``: + the case's step (40 per period);
4. ``own_wave``: + the pair's own wave at the sites (its standing part and the ring's non-uniformity), still planar
   and prescribed;
5. ``meridional``: + the sites' meridional motion (the full site rows);
6. ``elastic_pair``: + an elastic stator of one mode pair (the F(1,4) pair free, driven by the electrodes and loaded
   by the contact; the electrodes' static response of the other modes kept): the wave is no longer prescribed;
7. ``full``: + the full reduced basis (the other modes' compliance at the contact: local, tangential) = the model.

The swap: ``elastic_pair_planar`` takes step 6 before step 5 (4 -> 6' -> 6), to show how much the order matters.
Every run starts as the case does (harmonic start, rotor seated and at rest) and runs to the same end; the held
rotor is ``motion = "fixed"``. The rigid steps' ``wave_scale`` comes from the full run's wave at the same operating
point (mean over the sites of the normal displacement's first harmonic, the per-site tables) over the wave the
surgery prescribes at scale 1 (``results.transient.surgery.site_wave_m``, from a run of two periods).

The law (app/references/friction_drive.py) with the run's own W (its sites' normal wave), U_t (the prescribed
circumferential amplitude for a rigid wave, else the contact probe's circumferential amplitude), the penalty as
the Winkler stiffness, the band's slant width as the depth, N (the run's mean normal force), the wave's order
round the contact circle r_c, and μ = μ_d (1 + (FACT - 1) exp(-DC |s|)) = μ_s at DC = 0: the contact
half-angle θ_c from N, then the no-load deficit 1 - V_0 / (ω U_t) and stall / (μ N r_c) = 1 (the column
``stall_ratio_at_contact`` divides by μ N (r_c - W cos α) instead: the friction's lever is the contact point's).
The run's deficit is taken with two terms the law (first order in the wave) leaves out, both derived, not
fitted: the rotor's speed at the contact, Ω (r_c - W cos α) (the crest pushes the contact point in by the normal
wave's radial part), and the scheme's crest speed |g_v| U_t (:func:`scheme_speed_factor`, +0.23 % at the case's
step) instead of ω U_t; the uncorrected 1 - Ω r_c / (ω U_t) is the column ``deficit_raw``.

    .venv/bin/python bench/bench_motor_chain.py --out DIR [--case cases/wwusm-motor.toml] \
        [--set KEY=VALUE ...] [--free-ms 150 --free-min-periods 2000 --held-ms 60 --held-min-periods 2000 \
        --tolerance 2e-4 --window-periods 1000]

A riding rotor's full model may still creep after the steady-state rule (measured: +0.13 % per 100 periods at
2 200 periods on the coarse stator); continue it with a warm start and pass that run to ``--continued``:

    piezodyn run cases/wwusm-motor.toml --out DIR2 [the same --set] --set transient.end_time_s=0.2 \
        --set transient.steady_state.min_cycles=7600 --set transient.steady_state.relative_tolerance=0.0002 \
        --set 'transient.start_from="/abs/DIR/full-free"'

The bench writes DIR/chain.csv and DIR/chain.md (one row per run) and keeps every run's directory (a run whose directory
holds a summary of the same settings is read, not run again). The docs' tables: the case mesh (``--set
output.fields=false --set output.plots=false``) and the coarse stator of the tests (``--set
geometry.parameters.mesh_size_m=0.006 --set geometry.parameters.tip_mesh_size_m=0.002 --set
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
from forms.newmark import harmonic_rate_gains  # noqa: E402

HELD = 'transient.bodies[0].rotations[0].motion="fixed"'
#: (name, what it adds, surgery, site motion, the run it changes)
FINE, FINE_COULOMB = "fine", "fine_coulomb"      # half the case's steps; and a tenth of its regularisation (main)
#: (name, what it adds, surgery, site motion, extra settings, the run it changes)
STEPS = [
    ("travelling_law", "prescribed travelling wave, normal + circumferential; half the case's step, a tenth of its "
     "friction regularisation (the law's case)", "travelling_wave", "planar", FINE_COULOMB, None),
    ("travelling_reg", "+ the case's friction regularisation (0.1 mm/s)", "travelling_wave", "planar", FINE,
     "travelling_law"),
    ("travelling", "+ the case's step (40 per period)", "travelling_wave", "planar", [], "travelling_reg"),
    ("own_wave", "+ the pair's own wave shape round the ring (standing part, non-uniformity)", "rigid_wave",
     "planar", [], "travelling"),
    ("meridional", "+ meridional motion of the sites", "rigid_wave", "full", [], "own_wave"),
    ("elastic_pair", "+ elastic stator: the F(1,4) pair free, loaded by the contact", "modal_pair", "full", [],
     "meridional"),
    ("full", "+ the full reduced basis (the other modes' compliance) = the full model", "none", "full", [],
     "elastic_pair"),
    ("elastic_pair_planar", "swap: + elastic pair before the meridional motion", "modal_pair", "planar", [],
     "own_wave"),
]
COLUMNS = ["step", "adds", "point", "surgery", "site_motion", "wave_scale", "speed_rpm", "torque_mN_m",
           "normal_force_N", "wave_normal_um", "wave_circumferential_um", "wave_meridional_um", "separation",
           "theta_c_rad", "crest_speed_factor", "contact_radius_factor", "deficit_raw", "deficit", "deficit_law",
           "deficit_vs_law_pct", "stall_ratio", "stall_vs_law_pct", "stall_ratio_at_contact", "speed_change_pct",
           "torque_change_pct",
           "from_step", "periods", "steady", "window_periods", "speed_rpm_hw95", "torque_mN_m_hw95",
           "normal_force_N_hw95", "loop_wall_s", "run"]


def run(out: Path, name: str, case: Path, sets: list[str]) -> dict:
    """The run's summary (run now unless ``out/name`` holds one of the same settings)."""
    from app.runner import run_case

    directory = out / name
    record = directory / "chain_settings.json"
    if (directory / "summary.json").is_file() and record.is_file() and json.loads(record.read_text()) == sets:
        return json.loads((directory / "summary.json").read_text())
    print(f"chain: {name}: {' '.join(sets)}", flush=True)
    run_case(case, sets, directory, quiet=True)
    record.write_text(json.dumps(sets))
    return json.loads((directory / "summary.json").read_text())


def site_wave(directory: Path, contact: str = "stator_rotor", rows: int = 20) -> float:
    """Mean over the sites of the normal displacement's first-harmonic amplitude [m], last ``rows`` intervals."""
    import h5py

    with h5py.File(directory / "transient.h5", "r") as f:
        c = f[f"{contact}_sites_normal_displacement_cos"][-rows:]
        s = f[f"{contact}_sites_normal_displacement_sin"][-rows:]
    return float(np.hypot(c, s).mean())


def window_means(directory: Path, period_s: float, periods: int, batch: int = 20,
                 contact: str = "stator_rotor", body: str = "rotor") -> dict:
    """Means over the run's last ``periods`` drive periods of the rotor's speed [rad/s], the friction torque [N m]
    and the normal force [N] (time-weighted, per step), with the 95 % half-width of each from batch means of
    ``batch`` periods (app/intervals.py): a riding rotor's speed and torque wander over more than the motor
    statistic's 20-period window (a limit cycle of tens of periods, a creep over thousands)."""
    import h5py

    from app.intervals import half_width_95

    with h5py.File(Path(directory) / "transient.h5", "r") as f:
        t = f["time_s"][:]
        series = {"speed_rad_per_s": f[f"{body}_angular_velocity_rad_per_s"][:, 0],
                  "torque_N_m": f[f"{contact}_torque_N_m"][:, 0], "normal_force_N": f[f"{contact}_normal_force_N"][:]}
    n = periods // batch
    edges = t[-1] - period_s * batch * np.arange(n, -1, -1)
    out = {}
    for name, y in series.items():
        means = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            inside = (t > lo) & (t <= hi)
            means.append(np.trapz(y[inside], t[inside]) / (t[inside][-1] - t[inside][0]))
        out[name] = float(np.mean(means))
        out[name + "_hw95"] = half_width_95(np.asarray(means))
    out["window_periods"] = n * batch
    return out


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


def scheme_speed_factor(summary: dict, omega: float) -> float:
    """|g_v| / w: a steady harmonic q_n = Re(Q exp(i w n dt)) advanced by Newmark's update has the rate phasor g_v Q
    (app/reduced/engine.py ModalEngine._scheme_steady_inputs); for the trapezoidal rule (2 / (w dt)) tan(w dt / 2).
    The discrete crest speed is this factor times w U_t (at the closed-contact step)."""
    tr = summary["case"]["transient"]
    g_v, _ = harmonic_rate_gains(omega, tr["steps"]["closed_s"], tr["scheme"]["beta"], tr["scheme"]["gamma"])
    return abs(g_v) / omega


def read_summary(directory: Path) -> dict:
    return json.loads((Path(directory) / "summary.json").read_text())


def chain_row(summary: dict, directory: Path, point: str, scale: float, band_area_m2: float | None = None,
              window_periods: int | None = None) -> dict:
    """One run's chain quantities and the law's (module docstring): ``point`` 'free' (the deficit) or 'held' (the
    stall ratio); speed, torque and N the means over the last ``window_periods`` periods (:func:`window_means`;
    None: the motor statistic's window)."""
    tr = summary["results"]["transient"]
    motor = dict(tr["statistics"]["motor"])
    spread = {}
    if window_periods:
        means = window_means(directory, 1.0 / tr["drive_frequency_Hz"], window_periods)
        motor.update(speed_rad_per_s=means["speed_rad_per_s"], speed_rpm=means["speed_rad_per_s"] * 30 / math.pi,
                     friction_torque_N_m=means["torque_N_m"], normal_force_N=means["normal_force_N"])
        spread = {"speed_rpm_hw95": means["speed_rad_per_s_hw95"] * 30 / math.pi,
                  "torque_mN_m_hw95": 1e3 * means["torque_N_m_hw95"],
                  "normal_force_N_hw95": means["normal_force_N_hw95"],
                  "window_periods": means["window_periods"]}
    record = tr.get("surgery") or {}
    W = site_wave(directory)
    probe = motor.get("contact_point_amplitude_m", {})
    if record.get("surgery") in ("rigid_wave", "travelling_wave"):
        U = record["site_wave_m"]["circumferential_m"]          # prescribed, at the run's scale
    else:
        U = probe.get("tangential", float("nan"))
    if band_area_m2 is not None:
        tr["reduction"]["band_area_m2"] = [band_area_m2]
    lv = law_values(summary, W, U)
    omega = 2 * math.pi * tr["drive_frequency_Hz"]
    speed = motor["speed_rad_per_s"]
    crest = scheme_speed_factor(summary, omega)
    alpha = math.radians(summary["case"]["transient"]["contacts"][0]["half_angle_deg"])
    radius = 1.0 - W * math.cos(alpha) / lv["r_c"]
    free = point == "free"
    raw = 1.0 - speed * lv["r_c"] / (omega * U) if free else None
    deficit = 1.0 - speed * lv["r_c"] * radius / (crest * omega * U) if free else None
    stall = None if free else motor["friction_torque_N_m"] / (lv["mu"] * motor["normal_force_N"] * lv["r_c"])
    steady = tr.get("steady_state") or {}
    surgery = record.get("surgery", "none")
    return {
        "point": point, "surgery": surgery, "site_motion": record.get("site_motion", "full"), "wave_scale": scale,
        "speed_rpm": motor["speed_rpm"], "torque_mN_m": 1e3 * motor["friction_torque_N_m"],
        "normal_force_N": motor["normal_force_N"], "wave_normal_um": 1e6 * W, "wave_circumferential_um": 1e6 * U,
        "wave_meridional_um": 1e6 * probe.get("meridional", float("nan")),
        "separation": (motor.get("fractions") or {}).get("separation"),
        "theta_c_rad": lv.get("theta_c"), "deficit_raw": raw, "deficit": deficit,
        "crest_speed_factor": crest, "contact_radius_factor": radius,
        "deficit_law": lv.get("deficit_law") if free else None,
        "deficit_vs_law_pct": 100.0 * (deficit / lv["deficit_law"] - 1.0) if free and lv.get("deficit_law") else None,
        "stall_ratio": stall, "stall_vs_law_pct": 100.0 * (stall - 1.0) if stall is not None else None,
        "stall_ratio_at_contact": stall / radius if stall is not None else None,
        "periods": steady.get("cycles"), "steady": steady.get("steady"),
        "loop_wall_s": tr.get("stepping_wall_time_s"), "run": str(directory), **spread}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--case", type=Path, default=ROOT / "cases" / "wwusm-motor.toml")
    parser.add_argument("--set", action="append", default=[], dest="sets")
    parser.add_argument("--free-ms", type=float, default=150.0)
    parser.add_argument("--free-min-periods", type=int, default=2000)
    parser.add_argument("--held-ms", type=float, default=60.0)
    parser.add_argument("--held-min-periods", type=int, default=2000)
    parser.add_argument("--tolerance", type=float, default=2e-4,
                        help="the steady-state rule's relative tolerance over its 20 periods (the case's 5e-3 stops a "
                             "riding rotor that still creeps by 0.1 %% per 20 periods)")
    parser.add_argument("--window-periods", type=int, default=1000,
                        help="speed, torque and N: means over the last this many periods (batches of 20)")
    parser.add_argument("--continued", type=Path, default=None,
                        help="a run continuing DIR/full-free (transient.start_from): its row is added")
    parser.add_argument("--band-area-m2", type=float, default=None,
                        help="the contact band's area (default: the run's, results.transient.reduction)")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rule = f"transient.steady_state.relative_tolerance={args.tolerance!r}"
    points = {"free": [f"transient.end_time_s={args.free_ms * 1e-3!r}",
                       f"transient.steady_state.min_cycles={args.free_min_periods}", rule],
              "held": [f"transient.end_time_s={args.held_ms * 1e-3!r}",
                       f"transient.steady_state.min_cycles={args.held_min_periods}", rule, HELD]}
    base = list(args.sets) + ["output.contact_sites=true"]
    from app.case.schema import load_case

    steps = load_case(args.case, base).transient.steps
    fine = [f"transient.steps.{key}={getattr(steps, key) / 2!r}" for key in ("open_s", "closed_s", "change_s")]
    regularisation = load_case(args.case, base).transient.contacts[0].friction.regularisation_speed_m_per_s
    fine_coulomb = fine + [f"transient.contacts[0].friction.regularisation_speed_m_per_s={regularisation / 10!r}"]
    rows = []
    for point, point_sets in points.items():
        reference = run(out, f"full-{point}", args.case, base + point_sets)
        W_ref = site_wave(out / f"full-{point}")
        results = {}
        for name, _adds, surgery, motion, extra, _ in STEPS:
            extra = {FINE: fine, FINE_COULOMB: fine_coulomb}.get(extra, extra) if isinstance(extra, str) else extra
            sets = base + point_sets + [f'reduction.surgery="{surgery}"', f'reduction.site_motion="{motion}"'] + extra
            scale = 1.0
            if surgery in ("rigid_wave", "travelling_wave"):
                # the prescribed wave at scale 1 (two periods suffice: the surgery's record)
                probe = run(out, f"{name}-probe", args.case, base + [f'reduction.surgery="{surgery}"',
                                                                     f'reduction.site_motion="{motion}"',
                                                                     "transient.end_time_s=6e-5",
                                                                     "transient.steady_state.min_cycles=1"] + extra)
                scale = W_ref / probe["results"]["transient"]["surgery"]["site_wave_m"]["normal_m"]
                sets.append(f"reduction.wave_scale={scale!r}")
            summary = reference if surgery == "none" else run(out, f"{name}-{point}", args.case, sets)
            directory = out / (f"full-{point}" if surgery == "none" else f"{name}-{point}")
            results[name] = (summary, directory, scale)
        by_step = {}
        for name, adds, _surgery, _motion, _, before in STEPS:
            summary, directory, scale = results[name]
            row = chain_row(summary, directory, point, scale, args.band_area_m2, args.window_periods)
            prev = results.get(before)
            row.update({"step": name, "adds": adds, "from_step": before, "speed_change_pct": None,
                        "torque_change_pct": None})
            if prev is not None:
                pm = by_step[before]
                if point == "free":
                    row["speed_change_pct"] = 100.0 * (row["speed_rpm"] / pm["speed_rpm"] - 1.0)
                else:
                    row["torque_change_pct"] = 100.0 * (row["torque_mN_m"] / pm["torque_mN_m"] - 1.0)
            rows.append(row)
            by_step[name] = row
    if args.continued is not None:
        # the full model's no-load run continued (a warm start from DIR/full-free, module docstring)
        row = chain_row(read_summary(args.continued), args.continued, "free", 1.0, args.band_area_m2,
                        args.window_periods)
        before = next(r for r in rows if r["step"] == "elastic_pair" and r["point"] == "free")
        row.update({"step": "full_continued", "adds": "the full model's no-load run continued from its end",
                    "from_step": "elastic_pair", "torque_change_pct": None,
                    "speed_change_pct": 100.0 * (row["speed_rpm"] / before["speed_rpm"] - 1.0)})
        rows.append(row)
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
             "deficit (raw) | deficit | law | vs law | stall/(μNr_c) | change |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        change = r["speed_change_pct"] if r["point"] == "free" else r["torque_change_pct"]
        lines.append(
            f"| {r['step']} | {r['adds']} | {r['point']} | {_f(r['speed_rpm'], '.2f')} | {_f(r['torque_mN_m'], '.3f')}"
            f" | {_f(r['normal_force_N'], '.3f')} | {_f(r['wave_normal_um'], '.3f')}"
            f" | {_f(r['wave_circumferential_um'], '.3f')} | {_f(r['theta_c_rad'], '.4f')}"
            f" | {_f(r['deficit_raw'], '.5f')} | {_f(r['deficit'], '.5f')} | {_f(r['deficit_law'], '.5f')}"
            f" | {_f(r['deficit_vs_law_pct'], '+.1f')} %"
            f" | {_f(r['stall_ratio'], '.4f')} | {_f(change, '+.2f')} % from {r['from_step'] or '—'} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
