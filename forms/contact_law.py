"""The contact laws of :mod:`forms.contact` as scalar functions, for compiled kernels (the scalar twins).

:mod:`forms.contact` writes the penalty pressure and the regularised Coulomb friction as UFL, integrated over
facets by the FE tier. The modal tier's compiled loop (numba) and the rigid-rigid links evaluate the same laws
at points; these functions are that law, written once more only in the scalar form a kernel can call, and
``tests/test_contact_law.py`` checks them against the UFL form at sample points (values and derivatives).
They use ``math`` only and are compiled with ``numba.njit`` here, so a kernel calls them directly and Python
code (the FE tier's rigid links) calls the same compiled law.

Sign conventions as :mod:`forms.contact`: gap g < 0 is penetration, the pressure p >= 0 pushes the surfaces
apart; the friction force opposes the tangential slip velocity s of the surface over the obstacle.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit


class FrictionLaw(NamedTuple):
    """Regularised Coulomb friction (ANSYS names in brackets): kinetic coefficient [MU], static to kinetic
    ratio [FACT], exponential decay with slip speed [DC, s/m], the cap of the friction stress [TAUMAX, Pa]
    (a force [N] where the law acts on a force, the rigid links and node contacts) and the slip speed below
    which the law is viscous (regularisation) [m/s]."""

    mu_dynamic: float
    static_ratio: float = 1.0
    decay_s_per_m: float = 0.0
    shear_cap_Pa: float = 1e20
    regularisation_speed_m_per_s: float = 1e-4


@njit(cache=True)
def penalty_pressure(gap, gap_rate, stiffness, damping, rounding):
    """Kelvin-Voigt penalty pressure p [Pa] (or a force, per the unit of ``stiffness``) and its derivatives
    (p, dp/dg, dp/d(dg/dt)): p = < e(-g) - c dg/dt > while g < 0, 0 otherwise (no adhesion), with the
    elastic part e(d) = k d, or with ``rounding`` d0 > 0 the kink at first touch rounded (C^1):
    e(d) = k d^2 / (2 d0) for d < d0, k (d - d0 / 2) beyond. :func:`forms.contact.normal_pressure`."""
    if gap >= 0.0:
        return 0.0, 0.0, 0.0
    penetration = -gap
    if rounding > 0.0 and penetration < rounding:
        elastic = stiffness * penetration * penetration / (2.0 * rounding)
        slope = stiffness * penetration / rounding
    else:
        elastic = stiffness * (penetration - 0.5 * rounding) if rounding > 0.0 else stiffness * penetration
        slope = stiffness
    p = elastic - damping * gap_rate
    if p <= 0.0:
        return 0.0, 0.0, 0.0
    return p, -slope, -damping


@njit(cache=True)
def penalty_energy(gap, stiffness, rounding):
    """Elastic energy per area [J/m^2] stored by the penalty at gap g (the integral of e(d) over d)."""
    if gap >= 0.0:
        return 0.0
    d = -gap
    if rounding > 0.0:
        if d < rounding:
            return stiffness * d * d * d / (6.0 * rounding)
        return stiffness * (0.5 * d * d - 0.5 * rounding * d + rounding * rounding / 6.0)
    return 0.5 * stiffness * d * d


@njit(cache=True)
def friction_coefficient(speed, mu_dynamic, static_ratio, decay_s_per_m):
    """mu(|s|) = mu_d (1 + (FACT - 1) exp(-DC |s|)) and d mu / d|s|."""
    decay = math.exp(-decay_s_per_m * speed)
    return (mu_dynamic * (1.0 + (static_ratio - 1.0) * decay),
            -mu_dynamic * (static_ratio - 1.0) * decay_s_per_m * decay)


@njit(cache=True)
def friction_shear(speed, pressure, mu_dynamic, static_ratio, decay_s_per_m, cap):
    """The magnitude of the friction stress tau = min(mu(|s|) p, cap) [Pa] and (d tau/d|s|, d tau/dp).
    The force on the surface is -tau s / sqrt(|s|^2 + eps^2) (:func:`regularised_speed`)."""
    mu, dmu = friction_coefficient(speed, mu_dynamic, static_ratio, decay_s_per_m)
    tau = mu * pressure
    if tau > cap:
        return cap, 0.0, 0.0
    return tau, dmu * pressure, mu


@njit(cache=True)
def regularised_speed(speed_squared, regularisation_speed):
    """sqrt(|s|^2 + eps^2): the friction force is -tau s over this (viscous below eps, Coulomb above)."""
    return math.sqrt(speed_squared + regularisation_speed * regularisation_speed)


@njit(cache=True)
def slip_speed(speed_squared):
    """|s| as the UFL form forms it (sqrt(|s|^2 + 1e-30): no division by zero at s = 0)."""
    return math.sqrt(speed_squared + 1e-30)
