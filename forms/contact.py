"""Penalty contact of a deformable surface against a rigid body, and regularised Coulomb friction.

Sign conventions (used by ``app.transient``):

- The rigid obstacle's outward unit normal ``n`` points from the obstacle towards the deformable
  body. The normal gap g = (y - p) . n for a plane through p, g = |y - c| - R for a sphere,
  g = (rho - R - h tan(alpha)) cos(alpha) for a solid cone (see :func:`cone_gap`), with y = x + u
  the current position of a surface point; g < 0 is penetration.
- The contact pressure is p = < k (-g) + c (-dg/dt) > H(-g) >= 0 (Macaulay bracket <.>: no
  adhesion); the traction on the deformable surface is p n (+ friction), the force on the rigid
  body is minus its integral.
- Residual convention: r(u) = M a + C v + K u - f_ext - f_contact = 0, so the contact term that
  enters the residual form is ``-inner(traction, w) ds`` (see :func:`contact_residual`).

The gap depends on the deformable displacement u and the body position z only through y - z, so
the derivative with respect to z is minus the derivative with respect to u applied to a rigid
translation: the assembler needs only the tangent of :func:`contact_residual` with respect to u.
"""

from __future__ import annotations

import math

import ufl


def macaulay(x):
    """<x> = max(x, 0)."""
    return ufl.conditional(ufl.gt(x, 0), x, 0)


def heaviside(x):
    """H(x) = 1 for x > 0, else 0 (derivative of the Macaulay bracket)."""
    return ufl.conditional(ufl.gt(x, 0), 1, 0)


def plane_gap(y, plane_point, normal):
    """Normal gap [m] of points ``y`` to a plane through ``plane_point`` with unit ``normal``."""
    return ufl.dot(y - plane_point, normal)


def plane_normal(y, plane_point, normal):
    return normal


def sphere_gap(y, center, radius):
    """Normal gap [m] of points ``y`` to a sphere (circle in 2D) of ``radius`` about ``center``."""
    return ufl.sqrt(ufl.dot(y - center, y - center)) - radius


def sphere_gap_from_pole(e, pole, radius):
    """Gap [m] of the points y = center + radius * pole + e to the sphere, for a unit ``pole``:
    (|e|^2 + 2 R pole.e) / (|R pole + e| + R), the same value as |y - center| - R without its
    cancellation (|y - center| ~ R rounds at eps R: 2e-15 m at R = 10 m, which a 1e12 Pa/m penalty
    turns into residual noise above any Newton tolerance). Well conditioned where |e| << R, i.e.
    near the pole."""
    d = radius * pole + e
    return (ufl.dot(e, e) + 2 * radius * ufl.dot(pole, e)) / (ufl.sqrt(ufl.dot(d, d)) + radius)


def sphere_normal(y, center, radius):
    d = y - center
    return d / ufl.sqrt(ufl.dot(d, d))


def cone_gap(d, axis, radius, half_angle_rad):
    """Normal gap [m] of the points ``d`` (relative to a reference point p on the axis) to a solid
    cone about the unit ``axis`` through p whose conical face has ``radius`` at p and makes
    ``half_angle_rad`` (alpha) with the axis, the radius growing along ``axis``: with h = d.a and
    rho = |d - h a|, the face's radius at height h is R + h tan(alpha), and the distance normal to
    the face is g = (rho - R - h tan(alpha)) cos(alpha) (exact for points whose foot lies on the
    face, i.e. everywhere near it). Formed from d = y - p (small differences), so rho ~ R rounds at
    eps R (3e-18 m at 13 mm), not at eps |y|."""
    h = ufl.dot(d, axis)
    radial = d - h * axis
    rho = ufl.sqrt(ufl.dot(radial, radial))
    return (rho - radius - h * math.tan(half_angle_rad)) * math.cos(half_angle_rad)


def cone_normal(d, axis, half_angle_rad):
    """Outward unit normal of the cone face of :func:`cone_gap` at the points ``d``:
    n = cos(alpha) e_rho - sin(alpha) a, e_rho the unit radial direction (normal to the axis)."""
    radial = d - ufl.dot(d, axis) * axis
    e_rho = radial / ufl.sqrt(ufl.dot(radial, radial))
    return math.cos(half_angle_rad) * e_rho - math.sin(half_angle_rad) * axis


def excluding_initial_gap(gap, reference_gap):
    """Gap [m] measured from the reference configuration, as ANSYS's KEYOPT(9) = 1 ("exclude both
    initial geometrical penetration or gap"): g_eff = g(x + u, p) - g(x, p_ref), with ``reference_gap``
    the gap of the undeformed surface to the obstacle at its reference position. It depends on the
    mesh coordinates only, so the derivative with respect to u (the Newton tangent) is the gap's own.
    Both signs are removed: every point starts touching, none penetrates."""
    return gap - reference_gap


def normal_pressure(gap, gap_rate, stiffness, damping, rounding=0.0):
    """Kelvin-Voigt penalty pressure [Pa] (or force per length/area per the caller's stiffness
    unit): k (-g) + c (-dg/dt) while penetrating, clipped at zero so the surfaces never pull.

    ``rounding`` d0 > 0 [m] (a number) rounds the kink at first touch: the elastic part is k d^2 / (2 d0) for
    a penetration d = -g below d0 and k (d - d0 / 2) beyond (C^1, so a Newton iteration does not cycle when a
    point opens and closes within a step). The scalar twin: :func:`forms.contact_law.penalty_pressure`."""
    if not rounding:
        return heaviside(-gap) * macaulay(-stiffness * gap - damping * gap_rate)
    penetration = -gap
    elastic = ufl.conditional(ufl.lt(penetration, rounding), stiffness * penetration**2 / (2 * rounding),
                              stiffness * (penetration - 0.5 * rounding))
    return heaviside(-gap) * macaulay(elastic - damping * gap_rate)


def penalty_energy_density(gap, stiffness, rounding=0.0):
    """Elastic energy per area [J/m^2] the penalty stores at gap g (the integral of its elastic part)."""
    penetration = macaulay(-gap)
    if not rounding:
        return 0.5 * stiffness * penetration**2
    return ufl.conditional(ufl.lt(penetration, rounding), stiffness * penetration**3 / (6 * rounding),
                           stiffness * (0.5 * penetration**2 - 0.5 * rounding * penetration + rounding**2 / 6))


def friction_coefficient(slip_speed, mu_dynamic, static_ratio, decay_s_per_m):
    """ANSYS-style exponential static-to-kinetic law: mu = mu_d (1 + (FACT - 1) exp(-DC |s|)).
    mu_s = FACT mu_d at zero slip speed, mu_d at high slip speed."""
    return mu_dynamic * (1 + (static_ratio - 1) * ufl.exp(-decay_s_per_m * slip_speed))


def friction_traction(normal, relative_velocity, pressure, mu_dynamic, static_ratio, decay_s_per_m,
                      shear_cap, regularisation_speed):
    """Regularised Coulomb traction on the deformable surface [Pa], opposing the tangential slip
    velocity s = (I - n n) (v - v_body):

        t_t = -min(mu(|s|) p, TAUMAX) s / sqrt(|s|^2 + eps^2).

    Below the regularisation speed eps the law is a stiff viscous stick (|t_t| ~ mu p |s| / eps),
    which is what keeps Newton smooth through stick/slip transitions."""
    slip = relative_velocity - ufl.dot(relative_velocity, normal) * normal
    speed_reg = ufl.sqrt(ufl.dot(slip, slip) + regularisation_speed**2)
    speed = ufl.sqrt(ufl.dot(slip, slip) + 1e-30)
    mu = friction_coefficient(speed, mu_dynamic, static_ratio, decay_s_per_m)
    shear = ufl.min_value(mu * pressure, shear_cap)
    return -shear * slip / speed_reg


def contact_residual(traction, test, ds, weight=1.0):
    """Contribution of a surface traction [Pa] to the residual r = ... - f_contact; ``weight`` is the
    model's volume weight (2 pi r axisymmetric, thickness in plane strain)."""
    return -ufl.inner(traction, test) * weight * ds


def body_force_density(traction):
    """Force per area on the rigid body: the reaction of the traction on the deformable surface."""
    return -traction
