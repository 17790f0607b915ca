"""The stator's levers on the modal force F_m (docs/motor-stator.md, "Carrying 4.116 N"): for each design, the
wedge height that puts its converged F(1,4) on 36.065 kHz (secant on the Fourier model of order 4, plus the
measured 3D - 2D offset of the segmented wall), then the 3D model's F_m per volt, N / F_m at both preloads,
the pair's travelling-wave ratio and the mean field in the PZT.

    .venv/bin/python bench/bench_stator_levers.py --out results/levers [--designs base all-segment ...]
        [--offset-Hz 25.0] [--set KEY=VALUE ...]   (extra overrides for the 3D runs, e.g. a mesh)
        [--geometry KEY=VALUE ...]   (geometry overrides of every design, in the Fourier tuning and the 3D run)

--offset-Hz is F(1,4) of the converged 3D segmented stator minus that of its Fourier model at
mesh_refinement 4 (measured for the baseline by bench_stator_mesh.py; docs/motor-stator.md). A finished design
(OUT/<name>/3d/summary.json) is not run again.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_HZ = 36065.0
# the designs are overrides of the stator before issue 24 (one 2 mm layer, A/B segments, guards, full-height
# sensors); cases/wwusm-stator.toml is the design chosen from this bench (all-segment-multilayer-3)
STATOR = ROOT / "bench" / "cases" / "wwusm-stator-two-phase.toml"
FOURIER = ROOT / "bench" / "cases" / "wwusm-stator-two-phase-fourier.toml"
PZT_LIMIT_V_PER_MM = 354.0   # APC: 9 V AC per mil for Navy type I (PZT-4), the low end of 9-11 V/mil

TWO_PHASE = []
ALL_SEGMENT = [
    "geometry.parameters.negative_phase_segments=true", "geometry.parameters.sensor_height_m=0.001",
    'electrodes.common.facets=["inner"]',
    'electrodes.Am={facets=["Am1", "Am2", "Am3", "Am4"], kind="voltage", amplitude_V=200.0, phase_deg=180.0}',
    'electrodes.Bm={facets=["Bm1", "Bm2", "Bm3", "Bm4"], kind="voltage", amplitude_V=200.0, phase_deg=270.0}',
    'harmonic.wave.balance_with=["Bm"]']
MULTILAYER_REGIONS = ('regions=[{cells="base", material="steel"}, {cells="tube", material="pzt4", poling="radial"}, '
                      '{cells="tube_reversed", material="pzt4", poling="-radial"}, {cells="wedge", material="steel"}]')

DESIGNS = {
    "base": ("today's layout: A, B, guards, two sensors; one 2 mm PZT layer", [], TWO_PHASE),
    "all-segment": ("A+, B+, A-, B- segments; the sensors as 1 mm patches atop A-1 and B-1", [], ALL_SEGMENT),
    "multilayer-3": ("today's layout on a wall of 3 PZT layers (0.67 mm each)",
                     ["geometry.parameters.tube_layers=3", MULTILAYER_REGIONS], TWO_PHASE),
    "all-segment-multilayer-3": ("all-segment drive on a wall of 3 layers", ["geometry.parameters.tube_layers=3",
                                                                            MULTILAYER_REGIONS], ALL_SEGMENT),
    "all-segment-multilayer-3-wall-2.5": (
        "all-segment, 3 layers, 2.5 mm wall (r 11.0 - 13.5 mm): the field at 80 % of the 3-layer 2 mm wall's",
        ["geometry.parameters.tube_layers=3", MULTILAYER_REGIONS, "geometry.parameters.tube_inner_radius_m=0.011"],
        ALL_SEGMENT),
    "all-segment-wall-1.5": ("all-segment, one layer, 1.5 mm wall (r 12.0 - 13.5 mm)",
                             ["geometry.parameters.tube_inner_radius_m=0.012"], ALL_SEGMENT),
    "all-segment-tube-10": ("all-segment, one layer, 10 mm tube", ["geometry.parameters.tube_height_m=0.010"],
                            ALL_SEGMENT),
    "all-segment-tip-0.5": ("all-segment, one layer, 0.5 mm flat tip", ["geometry.parameters.tip_width_m=0.0005"],
                            ALL_SEGMENT),
}


def run(case: Path, out: Path, sets: list[str]) -> dict:
    summary = out / "summary.json"
    if not summary.is_file():
        cmd = [sys.executable, "-m", "app", "run", str(case), "--out", str(out), "--quiet"]
        cmd += [a for s in sets for a in ("--set", s)]
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        if proc.returncode != 0:
            raise SystemExit(f"{case.name} {sets} failed:\n{proc.stderr[-3000:]}")
    return json.loads(summary.read_text())


def circle_sets(geometry: list[str], wedge_m: float, three_d: bool) -> list[str]:
    """The sampling circles and the generatrix of this design: the contact circle 1.26 mm below its tip (the case's
    circle_height_m and circle_radius_m are the 3.0 mm wedge's), 80 um inside the inclined face as in the case."""
    from geometry.stator import StatorParameters

    prefix = "geometry.parameters."
    kw = {k[len(prefix):]: float(v) for k, v in (g.split("=", 1) for g in geometry if g.startswith(prefix))
          if k[len(prefix):] in ("tip_width_m", "tube_height_m", "tube_inner_radius_m", "collar_height_m",
                                 "base_height_m")}
    params = StatorParameters(**kw, wedge_height_m=wedge_m)
    r_c, z_c = params.contact_point()
    r_s = r_c + 0.00008
    sets = [f"modal.identify.circle_radius_m={r_s:.7f}", f"modal.identify.circle_height_m={z_c:.7f}",
            f"modal.identify.line_z_stop_m={params.tip_z_m - 0.00005:.7f}"]
    if three_d:
        sets += [f"modal.contact_force.circle_radius_m={r_s:.7f}", f"modal.contact_force.circle_height_m={z_c:.7f}",
                 f"harmonic.wave.circle_radius_m={r_s:.7f}", f"harmonic.wave.circle_height_m={z_c:.7f}"]
    return sets


def fourier_f14(out: Path, geometry: list[str], wedge_m: float) -> float:
    sets = [*[s for s in geometry if not s.startswith("regions=")], f"geometry.parameters.wedge_height_m={wedge_m:.7f}",
            *circle_sets(geometry, wedge_m, False), "output.fields=false", "output.plots=false"]
    if any(s.startswith("regions=") for s in geometry):
        sets.append(next(s for s in geometry if s.startswith("regions=")))
    return run(FOURIER, out / f"2d-{wedge_m * 1e3:.5f}mm", sets)["results"]["modal"]["working_resonance_Hz"]


def tune(out: Path, geometry: list[str], target_2d: float, start_m: float = 0.003) -> tuple[float, float]:
    """Wedge height [m] whose Fourier-model F(1,4) is target_2d (secant; ~1.5 kHz per mm)."""
    h0, h1 = start_m, start_m + 0.0002
    f0, f1 = fourier_f14(out, geometry, h0), fourier_f14(out, geometry, h1)
    for _ in range(8):
        if abs(f1 - target_2d) < 0.5:
            break
        h0, h1, f0 = h1, h1 + (target_2d - f1) * (h1 - h0) / (f1 - f0), f1
        f1 = fourier_f14(out, geometry, round(h1, 7))
    return round(h1, 7), f1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--designs", nargs="+", default=list(DESIGNS))
    parser.add_argument("--offset-Hz", type=float, required=True)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--geometry", dest="common", action="append", default=[],
                        help="a geometry override of every design "
                             "(e.g. geometry.parameters.wedge_root_fillet_m=0.0003)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    rows = []
    for name in args.designs:
        text, geometry, electrodes = DESIGNS[name]
        geometry = [*args.common, *geometry]
        start = time.perf_counter()
        d_out = out / name
        d_out.mkdir(parents=True, exist_ok=True)
        wedge, f2d = tune(d_out, geometry, TARGET_HZ - args.offset_Hz)
        s = run(STATOR, d_out / "3d", ["geometry.parameters.mesh_method=swept", *geometry, *electrodes,
                                       f"geometry.parameters.wedge_height_m={wedge}",
                                       *circle_sets(geometry, wedge, True),
                                       "output.fields=false", "output.plots=false", *args.overrides])
        modal = s["results"]["modal"]
        cf = modal["contact_force"]
        wave = s["results"].get("harmonic", {}).get("travelling_wave")
        params = s["case"]["geometry"]["parameters"]
        layers = params.get("tube_layers", 1)
        wall_mm = 1e3 * (params.get("tube_outer_radius_m", 0.0135) - params.get("tube_inner_radius_m", 0.0115))
        field = 200.0 * layers / wall_mm
        rows.append({"design": name, "what": text, "wedge_height_m": wedge, "fourier_f14_Hz": f2d,
                     "converged_f14_Hz": f2d + args.offset_Hz, "f14_3d_Hz": modal["working_resonance_Hz"],
                     "split_Hz": modal.get("working_partner_split_Hz"), "dofs": s["dofs"]["total"],
                     "F_m_per_V_N_per_V": cf["modal_force_per_volt_N_per_V"], "F_m_N": cf["modal_force_N"],
                     "N_over_F_m": [p["normal_force_over_modal_force"] for p in cf["preloads"]],
                     "free_amplitude_m": cf["free_normal_amplitude_m"], "k_m_N_per_m": cf["modal_stiffness_N_per_m"],
                     "two_mode_ratio": cf["two_mode_wave"]["travelling_wave_ratio"],
                     "harmonic_ratio_nominal": wave["nominal"]["travelling_wave_ratio"] if wave else None,
                     "harmonic_ratio_balanced": wave["travelling_wave_ratio"] if wave else None,
                     "field_V_per_mm": field, "field_over_limit": field / PZT_LIMIT_V_PER_MM,
                     "wall_s": time.perf_counter() - start, "load": os.getloadavg()[0]})
        (out / "levers.json").write_text(json.dumps(rows, indent=1))
        print(f"{name}: wedge {wedge * 1e3:.4f} mm, F_m {rows[-1]['F_m_per_V_N_per_V'] * 1e3:.2f} mN/V",
              file=sys.stderr, flush=True)
    print("| design | wedge height [mm] | F(1,4) converged (Fourier + offset) [Hz] | 3D F(1,4) on this mesh [Hz] "
          "| F_m per volt [mN/V] | F_m at 400 Vpp [N] | N/F_m at 0.98 N / 4.116 N | free amplitude W [um] "
          "| k_m [N/um] | travelling-wave ratio (two modes; harmonic nominal / balanced) | field [V/mm] (of limit) |")
    print("|" + "---|" * 11)
    for r in rows:
        harm = (f"; {r['harmonic_ratio_nominal']:.3f} / {r['harmonic_ratio_balanced']:.3f}"
                if r["harmonic_ratio_nominal"] is not None else "")
        print(f"| {r['design']} | {r['wedge_height_m'] * 1e3:.4f} | {r['converged_f14_Hz']:.1f} | {r['f14_3d_Hz']:.1f} "
              f"| {r['F_m_per_V_N_per_V'] * 1e3:.2f} | {r['F_m_N']:.2f} | {r['N_over_F_m'][0]:.2f} / "
              f"{r['N_over_F_m'][1]:.2f} | {r['free_amplitude_m'] * 1e6:.2f} | {r['k_m_N_per_m'] * 1e-6:.1f} "
              f"| {r['two_mode_ratio']:.3f}{harm} | {r['field_V_per_mm']:.0f} ({100 * r['field_over_limit']:.0f} %) |")


if __name__ == "__main__":
    main()
