"""Mean drive force of a travelling-wave friction drive (semi-analytic reference for the motor).

Model (Wallaschek, Smart Mater. Struct. 7 (1998) 369; Sattel, Hagedorn & Schmidt, J. Appl. Mech. 77
(2010) 031014), derived here again:

* the stator surface carries a travelling wave w = W cos xi, xi = k x - omega t, and its surface
  points move tangentially with u = U_t sin xi, so the crest moves against the wave at speed
  omega U_t cos xi (``surface_speed_m_per_s`` = omega U_t is its peak);
* a rigid slider rests on a quasi-static Winkler layer of normal stiffness k_w per area (no
  tangential compliance) and slides at speed V, counted positive in the drive direction (against
  the wave); Coulomb friction mu;
* the slider touches the crests over |xi| < theta_c; pressure k_w W (cos xi - cos theta_c), so the
  normal force per wavelength is N = (2 k_w W / k)(sin theta_c - theta_c cos theta_c);
* the surface is faster than the slider where cos xi > V / (omega U_t), i.e. over |xi| < phi with
  cos phi = V / (omega U_t) (phi = 0 for V >= omega U_t); there friction drives, elsewhere it brakes.
  With phi' = min(phi, theta_c), A = sin phi' - phi' cos theta_c, B = sin theta_c - theta_c cos theta_c:

      F / (mu N) = 2 A / B - 1,     mean force per length = (mu k_w W / pi)(2 A - B).

  F = mu N for V <= omega U_t cos theta_c (stall included: every point slides forward), F = -mu N
  for V >= omega U_t; the no-load speed V_0 (F = 0) is close to omega U_t: V_0 / (omega U_t) =
  cos phi_0 with 2 (sin phi_0 - phi_0 cos theta_c) = B, about 1 - 0.06 theta_c^2 for small theta_c.

What the contact does to the wave (the lumped motor, app/lumped/friction_drive.py, uses these): the crest
pressure's first harmonic in xi, mean over a wavelength of p cos xi = (k_w W / (2 pi)) C(theta_c) with
C = theta_c - sin theta_c cos theta_c (``crest_harmonic``), is in phase with the normal displacement: it
stiffens the wave. The friction traction is even in xi and works on the surface's tangential velocity
omega U_t cos xi: in quadrature with the displacement, it damps the wave by the mean power the surface gives
the slider, F V + (friction loss) (``dissipated_power_per_length``), since sign(s) s = |s|.

Units: SI throughout (m, s, N, Pa/m for k_w).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq


def layer_surface_amplitudes(normal_amplitude_m: float, tangential_amplitude_m: float, wavenumber_per_m: float,
                             thickness_m: float, poisson: float) -> tuple[float, float]:
    """(W_s, U_s) of the free face of a thin isotropic layer (plane strain) whose other face carries
    the wave u_x = U_t sin xi, u_z = W cos xi, quasi-statically, to first order in k h:

    * the free face carries no shear, so d(u_x)/dz = -d(u_z)/dx: U_s = U_t + k h W (the top of a
      bending plate moves further than its middle);
    * no normal stress on it in plane strain gives eps_zz = -nu / (1 - nu) eps_xx with
      eps_xx = k U_t cos xi: W_s = W - nu / (1 - nu) k h U_t.

    The neglected terms are O((k h)^2) relative (6e-4 % for the strip test)."""
    kh = wavenumber_per_m * thickness_m
    return (normal_amplitude_m - poisson / (1 - poisson) * kh * tangential_amplitude_m,
            tangential_amplitude_m + kh * normal_amplitude_m)


def layer_winkler(penalty_Pa_per_m: float, thickness_m: float, young_Pa: float, poisson: float) -> float:
    """Winkler stiffness [Pa/m] of a contact penalty in series with a thin layer pressed through its
    thickness with its other face held (uniaxial strain: constrained modulus E (1 - nu) / ((1 + nu)
    (1 - 2 nu)) over h); valid where the contact zone is long against h."""
    constrained = young_Pa * (1 - poisson) / ((1 + poisson) * (1 - 2 * poisson))
    return 1.0 / (1.0 / penalty_Pa_per_m + thickness_m / constrained)


def contact_integral(theta_c: float) -> float:
    """B(theta_c) = sin theta_c - theta_c cos theta_c (N = 2 k_w W B / k)."""
    return math.sin(theta_c) - theta_c * math.cos(theta_c)


def crest_harmonic(theta_c: float) -> float:
    """C(theta_c) = theta_c - sin theta_c cos theta_c = integral over |xi| < theta_c of (cos xi - cos theta_c)
    cos xi: the first harmonic of the crest pressure (over k_w W), the part of the contact force that loads the
    wave's normal mode shape cos xi (about 2 theta_c^3 / 3 = 2 B for small theta_c)."""
    return theta_c - math.sin(theta_c) * math.cos(theta_c)


def contact_half_angle(normal_force_per_wavelength_N: float, winkler_Pa_per_m: float, amplitude_m: float,
                       wavenumber_per_m: float) -> float:
    """theta_c [rad] in (0, pi] carrying N per wavelength; pi means the slider touches everywhere
    (the formula then needs the mean penetration as well, outside this model: ValueError)."""
    target = normal_force_per_wavelength_N * wavenumber_per_m / (2 * winkler_Pa_per_m * amplitude_m)
    if target <= 0:
        raise ValueError("normal force must be > 0")
    if target >= contact_integral(math.pi):
        raise ValueError("the preload presses the slider onto the troughs: contact all round")
    return brentq(lambda th: contact_integral(th) - target, 1e-12, math.pi, xtol=1e-15)


def force_ratio(speed_m_per_s, surface_speed_m_per_s: float, theta_c: float):
    """F / (mu N) at slider speed(s) V (array or scalar)."""
    v = np.asarray(speed_m_per_s, dtype=float)
    ratio = np.clip(v / surface_speed_m_per_s, -1.0, 1.0)
    phi = np.arccos(ratio)
    phi_eff = np.minimum(phi, theta_c)
    a = np.sin(phi_eff) - phi_eff * math.cos(theta_c)
    out = 2 * a / contact_integral(theta_c) - 1.0
    out = np.where(v >= surface_speed_m_per_s, -1.0, out)
    return float(out) if out.ndim == 0 else out


def no_load_speed(surface_speed_m_per_s: float, theta_c: float) -> float:
    """V_0 [m/s] where the mean force vanishes."""
    half = 0.5 * contact_integral(theta_c)
    phi0 = brentq(lambda p: math.sin(p) - p * math.cos(theta_c) - half, 0.0, theta_c, xtol=1e-15)
    return surface_speed_m_per_s * math.cos(phi0)


def speed_for_force(force_ratio_value: float, surface_speed_m_per_s: float, theta_c: float) -> float:
    """Slider speed V at which F / (mu N) equals the given value in (-1, 1)."""
    if not -1.0 < force_ratio_value < 1.0:
        raise ValueError("force ratio must lie in (-1, 1): at +-1 the speed is not unique")
    target = 0.5 * (force_ratio_value + 1.0) * contact_integral(theta_c)
    phi = brentq(lambda p: math.sin(p) - p * math.cos(theta_c) - target, 0.0, theta_c, xtol=1e-15)
    return surface_speed_m_per_s * math.cos(phi)


def dissipated_power_per_length(speed_m_per_s: float, surface_speed_m_per_s: float, theta_c: float, mu: float,
                                winkler_Pa_per_m: float, amplitude_m: float) -> float:
    """Mean power dissipated by friction per unit length of the wave and unit depth [W/m^2]: the
    average over a wavelength of mu p |s|, p = k_w W (cos xi - cos theta_c) on the crests and
    s = omega U_t cos xi - V the surface's speed relative to the slider."""
    def integrand(xi):
        return (math.cos(xi) - math.cos(theta_c)) * abs(surface_speed_m_per_s * math.cos(xi) - speed_m_per_s)

    ratio = speed_m_per_s / surface_speed_m_per_s
    stick = [math.acos(ratio)] if -1.0 < ratio < 1.0 and math.acos(ratio) < theta_c else []
    integral = 2 * quad(integrand, 0.0, theta_c, points=stick or None, epsabs=0.0, epsrel=1e-12)[0]
    return mu * winkler_Pa_per_m * amplitude_m * integral / (2 * math.pi)
