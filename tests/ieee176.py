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
