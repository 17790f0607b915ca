"""Diagnosis of the stator's travelling-wave ratio: Fourier orders of the normal amplitude round the
contact circle for A alone, B alone and A + iB; modal amplitudes of the F(1,4) pair.

Usage: python bench/diag_wave_orders.py [--case FILE] [--all] [--set key=value ...]
(--all: at both modes of the pair and their centre; default the centre only)"""

import math
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.case.schema import load_case  # noqa: E402
from app.fe.model import build_model  # noqa: E402
from app.fe.operators import add_damping, assemble_operators  # noqa: E402
from app.harmonic import HarmonicSolver  # noqa: E402
from app.modal import run_modal  # noqa: E402
from app.modeid import PointSet, circle_points, cylindrical, harmonics  # noqa: E402


def main(case_file, overrides):
    case = load_case(case_file, overrides)
    model = build_model(case, MPI.COMM_WORLD)
    ops = assemble_operators(model)
    modal = run_modal(model, ops)
    add_damping(ops, model, modal.working_mode.frequency_Hz)
    w_i = modal.working
    p_i = modal.orders[w_i].partner
    f1, f2 = sorted([modal.short[w_i].frequency_Hz, modal.short[p_i].frequency_Hz])
    print(f"DOFs {model.W.dofmap.index_map.size_global * model.W.dofmap.index_map_bs}")
    for k, m in enumerate(modal.short):
        o = modal.orders[k]
        print(f"mode {k}: {m.frequency_Hz:.2f} Hz (m={o.m}, n={o.n}, {o.component})")
    print(f"pair {f1:.2f} / {f2:.2f} Hz, split {f2 - f1:.2f} Hz, zeta*f = {0.002 * 0.5 * (f1 + f2):.1f} Hz")
    cfg = case.harmonic.wave
    pts, theta = circle_points(cfg.circle_radius_m, cfg.circle_height_m, cfg.n_points)
    probe = PointSet(model.mesh, pts)
    nr, nz = cfg.normal_rz
    norm = math.hypot(nr, nz)

    def normal(x):
        u = cylindrical(probe(model.displacement(x)), theta)
        return (u[:, 0] * nr + u[:, 2] * nz) / norm

    # pair modes' shapes at the circle: orientation of their n = 4 standing waves
    for k in (w_i, p_i):
        w = normal(modal.short[k].vector)
        c = harmonics(w)
        # w = 2|c4| cos(4 theta + arg c4)  -> antinode at theta = -arg(c4)/4
        print(f"mode {k} ({modal.short[k].frequency_Hz:.2f} Hz): n=4 antinode at "
              f"{math.degrees(-np.angle(c[4]) / 4) % 90:.2f} deg")

    def solve(phasors, f):
        solver = HarmonicSolver(model, ops, 200.0, prefix="diag_", phasors=phasors)
        try:
            point = solver.solve(f)
            x_re, x_im = (v.copy() for v in solver.full_solution())
        finally:
            solver.destroy()
        w = normal(x_re) + 1j * normal(x_im)
        q = {}
        for k in (w_i, p_i):  # modal amplitudes q_k = phi_k^T M x (mass-normalised modes)
            y = x_re.duplicate()
            ops.M.mult(modal.short[k].vector, y)
            q[k] = complex(y.dot(x_re), y.dot(x_im))
            y.destroy()
        return point, w, q

    def table(label, w):
        c = harmonics(w)
        n_pts = len(w)
        amp = np.abs(w)
        print(f"  {label}: min/max {amp.min() / amp.max():.4f}  (min {amp.min() * 1e6:.3f} um, "
              f"max {amp.max() * 1e6:.3f} um)")
        row = []
        for n in range(0, 17):
            fwd, bwd = abs(c[-n % n_pts]), abs(c[n % n_pts])
            if n == 0:
                row.append(f"n0 {fwd * 1e6:.4f}")
            else:
                row.append(f"n{n} +{fwd * 1e6:.4f}/-{bwd * 1e6:.4f}")
        print("   orders [um] (+theta / -theta): " + "; ".join(row))
        return c

    for f in ((f1, 0.5 * (f1 + f2), f2) if "--all" in sys.argv else (0.5 * (f1 + f2),)):
        print(f"--- at {f:.2f} Hz")
        pa, wa, qa = solve({"A": 200.0 + 0j, "B": 0j}, f)
        pb, wb, qb = solve({"A": 0j, "B": 200.0 + 0j}, f)
        ca = table("A alone (200 V, 0 deg)", wa)
        cb = table("B alone (200 V, 0 deg)", wb)
        table("A + iB", wa + 1j * wb)
        print(f"   modal amplitudes A: {qa[w_i]:.4g}, {qa[p_i]:.4g}; B: {qb[w_i]:.4g}, {qb[p_i]:.4g}")
        print(f"   |Y_A| alone {abs(pa.electrode_admittance_S['A']) * 1e3:.4f} mS, |Y_B| alone "
              f"{abs(pb.electrode_admittance_S['B']) * 1e3:.4f} mS")
        n = cfg.order
        for label, c in (("A", ca), ("B", cb)):
            p_, q_ = c[n], c[-n]  # w_n = p e^{i n theta} + q e^{-i n theta}
            antinode = math.degrees(-(np.angle(p_) - np.angle(q_)) / (2 * n))
            phase = math.degrees(0.5 * (np.angle(p_) + np.angle(q_)))
            print(f"   {label} alone n={n}: standing {2 * min(abs(p_), abs(q_)) * 1e6:.4f} um, antinode "
                  f"{antinode:.3f} deg (mod {180 / n:.1f}), temporal phase {phase:.3f} deg (mod 180)")
        fwd_a, bwd_a = ca[-n], ca[n]
        fwd_b, bwd_b = cb[-n], cb[n]
        # which of A + iB's n = 4 parts dominates: keep it, null the other with B's phasor beta
        dominant_bwd = abs(bwd_a + 1j * bwd_b) > abs(fwd_a + 1j * fwd_b)
        beta = -(fwd_a / fwd_b) if dominant_bwd else -(bwd_a / bwd_b)
        print(f"   balanced B phasor / A phasor: |beta| {abs(beta):.4f}, phase {math.degrees(np.angle(beta)):.2f} deg")
        table("A + beta B", wa + beta * wb)
    ops.destroy()


if __name__ == "__main__":
    args = sys.argv[1:]
    sets = [args[i + 1] for i in range(len(args)) if args[i] == "--set"]
    cases = [args[i + 1] for i in range(len(args)) if args[i] == "--case"]
    main(cases[0] if cases else ROOT / "cases" / "wwusm-stator.toml", sets)
