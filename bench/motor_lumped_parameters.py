"""The lumped motor's stator data (``[lumped.stator]`` of a friction_drive case) from a modal-tier reduced stator.

Reads a reduced model (the modal tier's cache file, ``reduced-*.npz`` in PIEZODYN_CACHE_DIR; building one is the
modal tier's job), solves its eigenproblem with the electrodes held (short circuit), and for the F(1,n) pair
nearest the drive evaluates each mode at the contact sites round the circle: the order-n amplitude W_x of the
normal displacement w = u . n (n the inclined face's normal towards the rotor, (-cos alpha, sin alpha) in (r, z)),
of the circumferential and meridional displacements; then, as app/modal.py:contact_force does on the FE model,
m_m = 1 / W_x^2, k_m = omega^2 m_m, zeta = x^T C x / (2 omega), F_m = |f| / W_x with f the drive's generalised
force on the mode, and U_t / W. It also solves the reduced stator's free harmonic response at the drive and prints
the wave the two-mode model predicts beside it (a check of the pair's data). Prints the TOML table.

    .venv/bin/python bench/motor_lumped_parameters.py /work/wt/cache/reduced-0ae509be3de47b50c19cd630.npz \\
        [--frequency-Hz 36065] [--volts A=200@0 B=200@90] [--order 4] [--half-angle-deg 15]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.linalg import eigh

from app.reduced.model import ReducedModel


def components(model: ReducedModel, q: np.ndarray, theta: np.ndarray, alpha: float):
    """(normal, circumferential, meridional) displacements at the contact sites of coordinates q."""
    u = (model.site_rows @ q).reshape(-1, model.gdim)
    ur = u[:, 0] * np.cos(theta) + u[:, 1] * np.sin(theta)
    ut = -u[:, 0] * np.sin(theta) + u[:, 1] * np.cos(theta)
    nr, nz = -math.cos(alpha), math.sin(alpha)
    return ur * nr + u[:, 2] * nz, ut, ur * nz - u[:, 2] * nr


def order_amplitude(values: np.ndarray, theta: np.ndarray, order: int) -> float:
    """Amplitude of order ``order`` of samples evenly round the circle: W for W cos(n theta) (real) or W e^{-i n
    theta} (a travelling phasor, one of the two harmonics)."""
    plus = abs(np.mean(values * np.exp(-1j * order * theta)))
    minus = abs(np.mean(values * np.exp(1j * order * theta)))
    return plus + minus


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reduced", help="a reduced stator (.npz of the modal tier's cache)")
    ap.add_argument("--frequency-Hz", type=float, default=36065.0)
    ap.add_argument("--volts", nargs="+", default=["A=200@0", "B=200@90"], help="NAME=AMPLITUDE@PHASE_DEG")
    ap.add_argument("--order", type=int, default=4)
    ap.add_argument("--half-angle-deg", type=float, default=15.0)
    args = ap.parse_args()
    model = ReducedModel.load(args.reduced)
    n = model.K.shape[0]
    held, free = model.input_coordinates, model.free_coordinates
    K, M, C = model.K, model.M, model.C
    omega2, X = eigh(K[np.ix_(free, free)], M[np.ix_(free, free)])
    freqs = np.sqrt(np.abs(omega2)) / (2 * math.pi)
    theta = np.arctan2(model.site_points[:, 1], model.site_points[:, 0])
    alpha = math.radians(args.half_angle_deg)
    volts = {}
    for item in args.volts:
        name, _, rest = item.partition("=")
        amplitude, _, phase = rest.partition("@")
        volts[name] = float(amplitude) * np.exp(1j * math.radians(float(phase or 0.0)))
    V = np.array([volts.get(name, 0.0) for name in model.inputs], dtype=complex)
    drive = 2 * math.pi * args.frequency_Hz
    rows = []
    for j in np.argsort(np.abs(freqs - args.frequency_Hz))[:6]:
        phi = np.zeros(n)
        phi[free] = X[:, j]
        w, ut, mer = components(model, phi, theta, alpha)
        W = order_amplitude(w, theta, args.order)
        # is it an order-n mode? (most of w's energy in order n)
        if W**2 / 2 < 0.5 * np.mean(w**2):
            continue
        omega = 2 * math.pi * freqs[j]
        coupling = K[np.ix_(free, held)] - omega**2 * M[np.ix_(free, held)] + 1j * omega * C[np.ix_(free, held)]
        force = -(X[:, j] @ coupling @ V)
        rows.append({"f": freqs[j], "W": W, "k": omega**2 / W**2, "zeta": phi @ C @ phi / (2 * omega),
                     "F": abs(force) / W, "ut": order_amplitude(ut, theta, args.order) / W,
                     "mer": order_amplitude(mer, theta, args.order) / W})
        if len(rows) == 2:
            break
    for r in rows:
        print(f"# mode {r['f']:.3f} Hz: W_x {r['W']:.5g} m/sqrt(kg), k_m {r['k']:.5g} N/m, zeta {r['zeta']:.5g}, "
              f"F_m {r['F']:.5g} N, U_t/W {r['ut']:.4f}, meridional/W {r['mer']:.4f}")
    volts_max = max(abs(v) for v in V)
    f_c = float(np.mean([r["f"] for r in rows]))
    k_m = float(np.mean([r["k"] for r in rows]))
    zeta = float(np.mean([r["zeta"] for r in rows]))
    force = math.sqrt(np.mean([r["F"] ** 2 for r in rows]))
    ratio = float(np.mean([r["ut"] for r in rows]))
    # the reduced stator's own free wave at the drive against the two-mode prediction
    D = K - drive**2 * M + 1j * drive * C
    x = np.zeros(n, dtype=complex)
    x[held] = V
    x[free] = np.linalg.solve(D[np.ix_(free, free)], -D[np.ix_(free, held)] @ x[held])
    w, ut, mer = components(model, x, theta, alpha)
    m_m = k_m / (2 * math.pi * f_c) ** 2
    two_mode = force / abs(k_m - m_m * drive**2 + 1j * drive * 2 * zeta * k_m / (2 * math.pi * f_c))
    print(f"# free wave at {args.frequency_Hz:g} Hz: reduced stator W {order_amplitude(w, theta, args.order):.5g} m "
          f"(|w| {np.abs(w).min():.4g}..{np.abs(w).max():.4g}), U_t {order_amplitude(ut, theta, args.order):.5g} m, "
          f"meridional {order_amplitude(mer, theta, args.order):.5g} m; two-mode model W {two_mode:.5g} m")
    print(f"# band area {float(model.band_area_m2[0]):.5g} m^2; contact radius "
          f"{float(np.hypot(*model.site_points[0, :2])):.10g} m")
    print("[lumped.stator]")
    print('source = "typed"')
    print(f"resonance_frequency_Hz = {f_c:.2f}")
    print(f"modal_stiffness_N_per_m = {k_m:.5g}")
    print(f"damping_ratio = {zeta:.5g}")
    print(f"force_per_volt_N_per_V = {force / volts_max:.5g}")
    print(f"tangential_ratio = {ratio:.4f}")


if __name__ == "__main__":
    main()
