"""Inertia and damping forms.

Damping follows the drill paper's eqs. (3)-(4): C = alpha M + beta K + sum_j beta_j K_j with
beta_j = 1 / (omega Q_m,j), K_j the mechanical stiffness of material j.
"""

from __future__ import annotations

import math

import ufl


def mass(u, v, rho, dx, weight=1.0):
    """Consistent mass form int rho u . v dV (rho [kg/m^3]; ``weight`` = volume weight, 2 pi r in
    axisymmetric models)."""
    return rho * ufl.inner(u, v) * weight * dx


def material_damping_beta(frequency_Hz: float, quality_factor: float) -> float:
    """beta_j = 1 / (omega Q_m) [s]: stiffness-proportional damping giving loss 1/Q at ``frequency_Hz``."""
    return 1.0 / (2 * math.pi * frequency_Hz * quality_factor)


def rayleigh_damping(mass_form, stiffness_forms, alpha_per_s: float, beta_s: float, betas_s):
    """C = alpha M + beta sum_j K_j + sum_j beta_j K_j as one form.

    ``stiffness_forms`` are the per-material mechanical stiffness forms K_j, ``betas_s`` their
    material betas; the global Rayleigh beta multiplies their sum (the whole structure)."""
    form = None
    if alpha_per_s:
        form = alpha_per_s * mass_form
    for K_j, beta_j in zip(stiffness_forms, betas_s):
        coeff = beta_s + beta_j
        if coeff:
            form = coeff * K_j if form is None else form + coeff * K_j
    return form
