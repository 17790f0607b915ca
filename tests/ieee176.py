"""IEEE Std 176 closed forms for the validation specimens, from the same material constants."""

import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import j0, j1

from forms import voigt


def bar_33(c, e, eps, density, length):
    """Length-extensional 33 bar (electrodes on the ends): (f_r, f_a, k33) [Hz, Hz, -].
    f_a = 1 / (2 L sqrt(rho s33^D)); f_r from k33^2 = (pi/2)(f_r/f_a) tan((pi/2)(f_a - f_r)/f_a)."""
    sE, d, epsT = voigt.e_form_to_d_form(c, e, eps)
    sD = voigt.open_circuit_compliance(c, e, eps)
    f_a = 1.0 / (2 * length * math.sqrt(density * sD[2, 2]))
    k33_sq = d[2, 2] ** 2 / (sE[2, 2] * epsT[2, 2])
    f_r = brentq(lambda f: (math.pi / 2) * (f / f_a) * math.tan((math.pi / 2) * (f_a - f) / f_a) - k33_sq,
                 0.2 * f_a, f_a * (1 - 1e-14))
    return f_r, f_a, math.sqrt(k33_sq)


def disc_radial(c, e, eps, density, radius):
    """Fundamental radial (planar) resonance of a thin, thickness-poled, short-circuited disc:
    f_r = eta c_p / (2 pi a), c_p = 1 / sqrt(rho s11^E (1 - sigma^2)), sigma = -s12^E/s11^E and
    eta the first root of eta J0(eta) = (1 - sigma) J1(eta)."""
    sE, _, _ = voigt.e_form_to_d_form(c, e, eps)
    sigma = -sE[0, 1] / sE[0, 0]
    c_p = 1.0 / math.sqrt(density * sE[0, 0] * (1 - sigma**2))
    eta = brentq(lambda x: x * j0(x) - (1 - sigma) * j1(x), 1.0, 3.0)
    return eta * c_p / (2 * math.pi * radius)


def observed_order(h, err):
    """Least-squares slope of log(err) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


def ring_hoop(c, e, eps, density, mean_radius):
    """Thin radially poled ring, electrodes on the curved faces: hoop-mode resonance
    f_r = 1 / (2 pi R sqrt(rho s11^E)) and antiresonance f_a = f_r / sqrt(1 - k31^2)."""
    sE, d, epsT = voigt.e_form_to_d_form(c, e, eps)
    f_r = 1.0 / (2 * math.pi * mean_radius * math.sqrt(density * sE[0, 0]))
    k31_sq = d[2, 0] ** 2 / (sE[0, 0] * epsT[2, 2])
    return f_r, f_r / math.sqrt(1 - k31_sq)


def strip_plane_strain_antiresonance(c, e, eps, density, length):
    """33 strip with S_yy = 0 and free lateral faces, open circuit (D3 = 0):
    f_a = 1 / (2 L sqrt(rho s'33)), s'33 = s33^D - (s23^D)^2 / s22^D."""
    sD = voigt.open_circuit_compliance(c, e, eps)
    s_eff = sD[2, 2] - sD[1, 2] ** 2 / sD[1, 1]
    return 1.0 / (2 * length * math.sqrt(density * s_eff))


def bar_33_capacitances(c, e, eps, density, length, area):
    """Capacitances [F] of the 33 bar's one-dimensional admittance (IEEE Std 176):
    Y = i omega C_LC / (1 - k33^2 tan(x) / x), x = omega L / (2 v^D), C_LC = eps33^T (1 - k33^2) A / L
    (longitudinally clamped). Returns (C_LC, C_1, C_0): C_1 the motional capacitance of the
    fundamental, from the residue of Y at f_r (Y ~ i omega C_1 omega_r^2 / (omega_r^2 - omega^2)), and
    C_0 = C_1 omega_r^2 / (omega_a^2 - omega_r^2) the shunt capacitance of the Butterworth-Van Dyke
    circuit that has the bar's f_r and f_a. C_0 is not C_LC: the higher modes' motional capacitances
    (n = 3, 5, ...) sit in parallel with C_LC near the fundamental, ~10 % for PZT-4."""
    f_r, f_a, k33 = bar_33(c, e, eps, density, length)
    _, _, epsT = voigt.e_form_to_d_form(c, e, eps)
    c_lc = epsT[2, 2] * (1 - k33**2) * area / length
    x_r, x_a = (math.pi / 2) * f_r / f_a, math.pi / 2
    # d/dx (1 - k^2 tan x / x) at x_r; C_1 = -2 C_LC / (x_r D'(x_r)) from the residue
    slope = -k33**2 * (1 / (math.cos(x_r) ** 2 * x_r) - math.tan(x_r) / x_r**2)
    c_1 = -2 * c_lc / (x_r * slope)
    return c_lc, c_1, c_1 * x_r**2 / (x_a**2 - x_r**2)


def rayleigh_love_factor(poisson, radius, length, order=1):
    """Frequency factor of a thin rod's lateral inertia (Rayleigh-Love): f = f_1D (1 - (nu n pi r_g / L)^2 / 2)
    with r_g^2 = r^2 / 2 the polar radius of gyration of a round section; error O((nu k r)^4)."""
    return 1.0 - 0.5 * (poisson * order * math.pi * radius / length) ** 2 / 2


def blocked_stress_33(c, e, E3, lateral: str = "blocked"):
    """Axial stress T3 [Pa] of a bar poled along 3 whose length is held (S3 = 0) in a uniform field E3 [V/m],
    from T = c^E S - e^T E: every strain held ("blocked"), T3 = -e33 E3; sides free ("free", T1 = T2 = 0), the
    lateral strain S1 = S2 = e31 E3 / (c11 + c12) adds 2 c13 S1."""
    if lateral == "blocked":
        return -e[2, 2] * E3
    lateral_strain = e[2, 0] * E3 / (c[0, 0] + c[0, 1])
    return 2 * c[0, 2] * lateral_strain - e[2, 2] * E3
