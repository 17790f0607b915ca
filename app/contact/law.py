"""The contact law at a point, compiled (numba), for every tier that evaluates contacts at points: the modal
tier's loop (app/reduced/kernel.py) and the FE tier's per-site diagnostics (app/transient/engine.py).

A *site* is a point of a deformable surface (a surface contact's sample point, a node contact's node) with an
area, a reference position and a frame; it presses against the obstacle shape of a rigid body (plane, sphere,
cone; a node contact: a sphere along a fixed normal) with the penalty law of forms/contact_law.py (the scalar
twins of the FE tier's UFL) and regularised Coulomb friction, the body's spin in the slip. Rigid-rigid links
(Kelvin-Voigt, optional friction) act between bodies. Records (NamedTuples of arrays) carry the data:
:class:`Bodies`, :class:`Sites`, :class:`Contacts`, :class:`Links` (built from a case by app/contact/records.py).

The functions a time step calls are compiled without reference counting (``_nrt=False``, why: the cost note in
app/reduced/kernel.py): they neither allocate nor return arrays, their work arrays come from the caller.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from forms import contact_law as _law

_penalty_pressure = _law.penalty_pressure
_penalty_energy = _law.penalty_energy
_friction_shear = _law.friction_shear
_friction_coefficient = _law.friction_coefficient

# contact kinds and shapes
SURFACE, NODE = 0, 1
PLANE, SPHERE, CONE = 0, 1, 2


class Bodies(NamedTuple):
    """Rigid bodies, their coordinates packed body-major (translations, then angles)."""

    gdim: int
    start: np.ndarray         # (n_bodies,) first coordinate of each body
    mass: np.ndarray          # (m,) mass [kg] on translations, inertia [kg m^2] on angles
    free: np.ndarray          # (m,) bool
    load: np.ndarray          # (m,) constant generalized load: gravity + applied force [N], torque [N m]
    brake: np.ndarray         # (m,) viscous brake [N m s/rad] of a free angle
    axis: np.ndarray          # (m, 3) rotation axis of an angle coordinate (zeros on translations)
    rate: np.ndarray          # (m,) prescribed rate of a held coordinate [m/s or rad/s] (0: held still)
    reference: np.ndarray     # (n_bodies, 3) reference point (the case's position_m)


class Sites(NamedTuple):
    """Contact sites on the structure: displacement rows, reference geometry, area, contact."""

    rows: np.ndarray          # (n_sites * gdim, n) y_site = rows @ q
    rel: np.ndarray           # (n_sites, 3) x - (body reference + obstacle offset), or - (... + R pole)
    lever: np.ndarray         # (n_sites, 3) x - body reference
    gap_ref: np.ndarray       # (n_sites,) reference gap excluded (exclude_initial_gap), else 0
    weight: np.ndarray        # (n_sites,) area [m^2] of a surface site, 1 for a node site
    contact: np.ndarray       # (n_sites,) contact index
    frame: np.ndarray         # (n_sites, 3, 3) reporting frame: rows n, e1 (along the spin), e2


class Contacts(NamedTuple):
    """Laws of the contacts that act through sites (surface and node contacts)."""

    kind: np.ndarray          # SURFACE or NODE
    shape: np.ndarray         # PLANE, SPHERE, CONE (node: a sphere along a fixed normal)
    body: np.ndarray
    vector: np.ndarray        # (n, 3): plane normal / sphere pole (zeros: none) / cone axis / node normal
    radius: np.ndarray        # sphere radius, cone radius at the body's reference point
    half_angle: np.ndarray    # cone [rad]
    stiffness: np.ndarray     # [Pa/m] surface, [N/m^exponent] node
    damping: np.ndarray       # [Pa s/m] surface, [N s/m] node
    rounding: np.ndarray      # [m] (surface)
    exponent: np.ndarray      # force law exponent (node; surface 1)
    mu: np.ndarray            # mu_d (0: frictionless)
    fact: np.ndarray
    decay: np.ndarray
    cap: np.ndarray           # shear cap [Pa] surface, force cap [N] node
    eps: np.ndarray           # regularisation speed [m/s]


class Links(NamedTuple):
    """Rigid-rigid Kelvin-Voigt links: the force acts along ``direction`` from lower to upper."""

    lower: np.ndarray
    upper: np.ndarray
    direction: np.ndarray     # (n, 3)
    touch: np.ndarray         # reference-point distance at first touch [m]
    stiffness: np.ndarray
    damping: np.ndarray
    offset: np.ndarray        # upper body's reference point to the contact point, against direction [m]
    mu: np.ndarray
    fact: np.ndarray
    decay: np.ndarray
    cap: np.ndarray
    eps: np.ndarray


# ------------------------------------------------------------------ small vector helpers
@njit(cache=True, _nrt=False)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, _nrt=False)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


# ------------------------------------------------------------------ obstacle shapes
@njit(cache=True, _nrt=False)
def shape_gap(shape, vector, radius, half_angle, d, n, Dn):
    """Gap [m] of a point at ``d`` (3-vector relative to the obstacle's reference point; for a sphere with a
    pole, relative to centre + R pole) and the obstacle's outward unit normal ``n`` there; ``Dn`` = dn/dd.
    Plane: g = n.d. Sphere: |d| - R (with a pole, without its cancellation, as forms/contact.py).
    Cone about the unit axis a, radius R at the reference, half angle alpha: g = (rho - R - h tan a) cos a."""
    for i in range(3):
        for j in range(3):
            Dn[i, j] = 0.0
    if shape == PLANE:
        for i in range(3):
            n[i] = vector[i]
        return _dot3(vector, d)
    if shape == SPHERE:
        pole = vector[0] != 0.0 or vector[1] != 0.0 or vector[2] != 0.0
        if pole:
            ee = _dot3(d, d)
            pe = _dot3(vector, d)
            c0 = radius * vector[0] + d[0]
            c1 = radius * vector[1] + d[1]
            c2 = radius * vector[2] + d[2]
            dist = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            gap = (ee + 2.0 * radius * pe) / (dist + radius)
            n[0], n[1], n[2] = c0 / dist, c1 / dist, c2 / dist
        else:
            dist = math.sqrt(_dot3(d, d))
            gap = dist - radius
            for i in range(3):
                n[i] = d[i] / dist
        for i in range(3):
            for j in range(3):
                Dn[i, j] = ((1.0 if i == j else 0.0) - n[i] * n[j]) / dist
        return gap
    # cone
    h = _dot3(d, vector)
    r0 = d[0] - h * vector[0]
    r1 = d[1] - h * vector[1]
    r2 = d[2] - h * vector[2]
    rho = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    ca, sa = math.cos(half_angle), math.sin(half_angle)
    e0, e1, e2 = r0 / rho, r1 / rho, r2 / rho
    n[0] = ca * e0 - sa * vector[0]
    n[1] = ca * e1 - sa * vector[1]
    n[2] = ca * e2 - sa * vector[2]
    e = (e0, e1, e2)
    for i in range(3):
        for j in range(3):
            Dn[i, j] = ca * ((1.0 if i == j else 0.0) - vector[i] * vector[j] - e[i] * e[j]) / rho
    return (rho - radius - h * math.tan(half_angle)) * ca


# ------------------------------------------------------------------ one site's force
@njit(cache=True, _nrt=False)
def friction_tangent(T, dT_dfn, dT_dspeed, s, reg, speed, A, b):
    """Derivatives of the regularised friction force f_t = -T(fn, |s|) s / reg(|s|) (forms/contact_law.py) at the
    slip ``s`` [m/s]: ``A`` = d f_t / d s (3 x 3), ``b`` = d f_t / d fn (3), written in place. ``T`` is the shear
    magnitude [N], ``dT_dfn`` and ``dT_dspeed`` its derivatives, ``reg`` the regularised speed, ``speed`` |s|."""
    r3 = reg * reg * reg
    for r in range(3):
        b[r] = -dT_dfn * s[r] / reg
        for k in range(3):
            A[r, k] = -T * ((1.0 if r == k else 0.0) / reg - s[r] * s[k] / r3) \
                - s[r] / reg * dT_dspeed * s[k] / speed


@njit(cache=True, _nrt=False)
def site_position(i, y, z_mid, sites, b, bodies, d, lever):
    """Site i's position relative to its body b's obstacle, ``d`` (3) [m], and its lever arm from the body's reference
    point, ``lever`` (3) [m], at the site's displacement ``y`` and the bodies' mid-point coordinates: the reference
    ones (sites.rel, sites.lever) moved by the site's displacement less the body's translation. Both the law
    (:func:`site_force`) and the modal kernel's test of a surely open site form them here."""
    s0 = bodies.start[b]
    for k in range(3):
        d[k] = sites.rel[i, k]
        lever[k] = sites.lever[i, k]
    for k in range(bodies.gdim):
        du = y[k] - (z_mid[s0 + k] - bodies.reference[b, k])
        d[k] += du
        lever[k] += du


@njit(cache=True, _nrt=False)
def site_force(i, y, v_site, z_mid, zd_mid, sites, contacts, bodies, c_vel, w_f, want, out):
    """Force of site i on the structure (``out.f``, 3) at the mid-point state: the site's displacement ``y`` and
    velocity ``v_site`` (3-vectors), the bodies' mid-point coordinates and rates. With ``want``, the
    derivatives with respect to the site's own increment (``out.Fd``, 3 x 3) and to the increments of its
    body's coordinates (``out.Fz``, 3 x n_body_coordinates), both per unit end-of-step increment (the
    generalized-alpha factors w_f and c_vel included). Returns (normal force [N], gap [m], slip e1, slip e2,
    slip speed). ``out.lever`` gets the lever arm from the body's reference point."""
    c = sites.contact[i]
    b = contacts.body[c]
    gdim = bodies.gdim
    s0 = bodies.start[b]
    n_rot = (bodies.start[b + 1] if b + 1 < bodies.start.size else bodies.mass.size) - s0 - gdim
    d = out.d
    lever = out.lever
    site_position(i, y, z_mid, sites, b, bodies, d, lever)
    omega = out.omega
    omega[0] = omega[1] = omega[2] = 0.0
    for r in range(n_rot):
        j = s0 + gdim + r
        for k in range(3):
            omega[k] += zd_mid[j] * bodies.axis[j, k]
    spin = out.spin
    _cross(omega, lever, spin)
    vrel = out.vrel
    for k in range(3):
        vrel[k] = (v_site[k] - zd_mid[s0 + k] if k < gdim else v_site[k]) - spin[k]
    n = out.n
    Dn = out.Dn
    kind = contacts.kind[c]
    if kind == NODE:
        for k in range(3):
            n[k] = contacts.vector[c, k]
            for j in range(3):
                Dn[k, j] = 0.0
        gap = _dot3(n, d) - contacts.radius[c] - sites.gap_ref[i]
    else:
        gap = shape_gap(contacts.shape[c], contacts.vector[c], contacts.radius[c], contacts.half_angle[c], d, n,
                        Dn) - sites.gap_ref[i]
    f = out.f
    f[0] = f[1] = f[2] = 0.0
    if want:
        for r in range(3):
            for k in range(3):
                out.Fd[r, k] = 0.0
            for k in range(out.Fz.shape[1]):
                out.Fz[r, k] = 0.0
    rate = _dot3(n, vrel)
    if gap >= 0.0:
        return 0.0, gap, 0.0, 0.0, 0.0
    weight = sites.weight[i]
    if kind == NODE:
        delta = -gap
        power = delta ** contacts.exponent[c]
        fn = contacts.stiffness[c] * power - contacts.damping[c] * rate
        if fn <= 0.0:
            return 0.0, gap, 0.0, 0.0, 0.0
        dfn_dg = -contacts.exponent[c] * contacts.stiffness[c] * power / delta
        dfn_drate = -contacts.damping[c]
    else:
        p, dp_dg, dp_drate = _penalty_pressure(gap, rate, contacts.stiffness[c], contacts.damping[c],
                                               contacts.rounding[c])
        if p <= 0.0:
            return 0.0, gap, 0.0, 0.0, 0.0
        fn = weight * p
        dfn_dg = weight * dp_dg
        dfn_drate = weight * dp_drate
    # slip: the tangential relative velocity
    s = out.s
    for k in range(3):
        s[k] = vrel[k] - rate * n[k]
    speed2 = _dot3(s, s)
    speed = math.sqrt(speed2 + 1e-30)
    T = 0.0
    dT_dspeed = 0.0
    dT_dfn = 0.0
    mu = contacts.mu[c]
    reg = 1.0
    if mu > 0.0:
        eps = contacts.eps[c]
        reg = math.sqrt(speed2 + eps * eps)
        T, dT_dspeed, dT_dfn = _friction_shear(speed, fn, mu, contacts.fact[c], contacts.decay[c],
                                               contacts.cap[c] * weight)
    for k in range(3):
        f[k] = fn * n[k] - T * s[k] / reg
    e1 = sites.frame[i, 1]
    e2 = sites.frame[i, 2]
    s1 = _dot3(s, e1)
    s2 = _dot3(s, e2)
    if not want:
        return fn, gap, s1, s2, speed
    # derivatives with respect to the relative position d and the relative velocity v
    # g: dg/dd = n; rate = n.v: d rate/dd = v^T Dn, d rate/dv = n
    vDn = out.vDn
    for k in range(3):
        vDn[k] = vrel[0] * Dn[0, k] + vrel[1] * Dn[1, k] + vrel[2] * Dn[2, k]
    dfn_dd = out.dfn_dd
    dfn_dv = out.dfn_dv
    for k in range(3):
        dfn_dd[k] = dfn_dg * n[k] + dfn_drate * vDn[k]
        dfn_dv[k] = dfn_drate * n[k]
    # s = v - (n.v) n: ds/dv = P, ds/dd = -(n vDn^T + rate Dn)
    A = out.A             # d f_t / d s
    bvec = out.b          # d f_t / d fn
    if mu > 0.0:
        friction_tangent(T, dT_dfn, dT_dspeed, s, reg, speed, A, bvec)
    else:
        for r in range(3):
            bvec[r] = 0.0
            for k in range(3):
                A[r, k] = 0.0
    Jd = out.Jd           # d f / d d
    Jv = out.Jv           # d f / d v
    for r in range(3):
        for k in range(3):
            jd = (n[r] + bvec[r]) * dfn_dd[k] + fn * Dn[r, k]
            jv = (n[r] + bvec[r]) * dfn_dv[k]
            for m in range(3):
                ds_dd_m = -(n[m] * vDn[k] + rate * Dn[m, k])
                ds_dv_m = (1.0 if m == k else 0.0) - n[m] * n[k]
                jd += A[r, m] * ds_dd_m
                jv += A[r, m] * ds_dv_m
            Jd[r, k] = jd
            Jv[r, k] = jv
    # chain to the unknowns: d(d)/d(site increment) = w_f I, d(v)/d(...) = w_f (c_vel I - [omega]x)
    # body translation: d(d)/dz = -w_f I, dv/dz = -w_f (c_vel I - [omega]x);
    # angle k: dv/dtheta_k = -w_f c_vel a_k x lever
    for r in range(3):
        for k in range(3):
            om = 0.0        # ([omega]x)[m, k] applied: Jv @ [omega]x
            for m in range(3):
                # [omega]x e_k = omega x e_k: component m
                if m == 0:
                    wx = omega[1] * (1.0 if k == 2 else 0.0) - omega[2] * (1.0 if k == 1 else 0.0)
                elif m == 1:
                    wx = omega[2] * (1.0 if k == 0 else 0.0) - omega[0] * (1.0 if k == 2 else 0.0)
                else:
                    wx = omega[0] * (1.0 if k == 1 else 0.0) - omega[1] * (1.0 if k == 0 else 0.0)
                om += Jv[r, m] * wx
            out.Fd[r, k] = w_f * (Jd[r, k] + c_vel * Jv[r, k] - om)
    for k in range(gdim):
        for r in range(3):
            out.Fz[r, k] = -out.Fd[r, k]
    axl = out.axl
    for q in range(n_rot):
        j = s0 + gdim + q
        _cross(bodies.axis[j], lever, axl)
        for r in range(3):
            out.Fz[r, gdim + q] = -w_f * c_vel * (Jv[r, 0] * axl[0] + Jv[r, 1] * axl[1] + Jv[r, 2] * axl[2])
    return fn, gap, s1, s2, speed


class SiteWork(NamedTuple):
    d: np.ndarray
    lever: np.ndarray
    omega: np.ndarray
    spin: np.ndarray
    vrel: np.ndarray
    n: np.ndarray
    Dn: np.ndarray
    f: np.ndarray
    s: np.ndarray
    vDn: np.ndarray
    dfn_dd: np.ndarray
    dfn_dv: np.ndarray
    A: np.ndarray
    b: np.ndarray
    Jd: np.ndarray
    Jv: np.ndarray
    Fd: np.ndarray
    Fz: np.ndarray
    axl: np.ndarray


@njit(cache=True)
def site_work(max_body_coordinates):
    return SiteWork(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros((3, 3)),
                    np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros((3, 3)), np.zeros(3),
                    np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, max(max_body_coordinates, 1))),
                    np.zeros(3))


# ------------------------------------------------------------------ rigid-rigid links
@njit(cache=True, _nrt=False)
def _body_rotations(bodies, b):
    s0 = bodies.start[b]
    end = bodies.start[b + 1] if b + 1 < bodies.start.size else bodies.mass.size
    return s0, end - s0 - bodies.gdim


@njit(cache=True, _nrt=False)
def link_force(l, z_mid, zd_mid, bodies, links, F, P, want, work):
    """Force of link l on its upper body (``F``, 3) at the mid-point state; ``P`` (3 x m) gets the map from
    all body coordinate rates to the slip velocity of the contact point (upper's over lower's); ``work`` (5, 3)
    scratch. Returns
    (normal force, penetration, rate, dF/d delta [N/m], dF/d rate [N s/m], regularised friction terms as
    (T, dT/dspeed, dT/dfn, reg, speed) or zeros)."""
    gdim = bodies.gdim
    lo, up = links.lower[l], links.upper[l]
    slo, nlo = _body_rotations(bodies, lo)
    sup, nup = _body_rotations(bodies, up)
    n = links.direction[l]
    delta = links.touch[l]
    rate = 0.0
    for k in range(gdim):
        delta -= n[k] * (z_mid[sup + k] - z_mid[slo + k])
        rate -= n[k] * (zd_mid[sup + k] - zd_mid[slo + k])
    F[0] = F[1] = F[2] = 0.0
    for r in range(3):
        for k in range(P.shape[1]):
            P[r, k] = 0.0
    if delta <= 0.0:
        return 0.0, delta, rate, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0
    f = links.stiffness[l] * delta + links.damping[l] * rate
    if f <= 0.0:
        return 0.0, delta, rate, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0
    for k in range(3):
        F[k] = f * n[k]
    if links.mu[l] <= 0.0 and nlo + nup == 0:
        return f, delta, rate, links.stiffness[l], links.damping[l], 0.0, 0.0, 0.0, 1.0, 0.0
    # slip map: translations, then omega x r of each body's lever arm (upper: -offset n; lower: to that point)
    r_up = work[0]
    r_lo = work[1]
    for k in range(3):
        r_lo[k] = 0.0
    for k in range(3):
        r_up[k] = -links.offset[l] * n[k]
    for k in range(gdim):
        r_lo[k] = (z_mid[sup + k] - z_mid[slo + k]) + r_up[k]
    axr = work[2]
    for k in range(gdim):
        P[k, sup + k] += 1.0
        P[k, slo + k] -= 1.0
    for q in range(nup):
        j = sup + gdim + q
        _cross(bodies.axis[j], r_up, axr)
        for k in range(3):
            P[k, j] += axr[k]
    for q in range(nlo):
        j = slo + gdim + q
        _cross(bodies.axis[j], r_lo, axr)
        for k in range(3):
            P[k, j] -= axr[k]
    if links.mu[l] <= 0.0:
        return f, delta, rate, links.stiffness[l], links.damping[l], 0.0, 0.0, 0.0, 1.0, 0.0
    vrel = work[3]
    for k in range(3):
        vrel[k] = 0.0
        for j in range(P.shape[1]):
            vrel[k] += P[k, j] * zd_mid[j]
    vn = _dot3(vrel, n)
    s = work[4]
    for k in range(3):
        s[k] = vrel[k] - vn * n[k]
    speed2 = _dot3(s, s)
    speed = math.sqrt(speed2 + 1e-30)
    reg = math.sqrt(speed2 + links.eps[l] * links.eps[l])
    T, dT_ds, dT_dfn = _friction_shear(speed, f, links.mu[l], links.fact[l], links.decay[l], links.cap[l])
    for k in range(3):
        F[k] -= T * s[k] / reg
    return f, delta, rate, links.stiffness[l], links.damping[l], T, dT_ds, dT_dfn, reg, speed


class SiteSample(NamedTuple):
    """One site at one step, what the diagnostics accumulate (:func:`accumulate_site`): its normal force ``fn`` [N],
    slip s1 = s.e1, s2 = s.e2 and ``speed`` = |s| [m/s], friction shear stress ``tau`` [Pa], normal displacement
    towards the obstacle ``un`` = -n.y [m], ``area`` [m^2], and ``eps``, the friction's regularisation speed [m/s]
    (inf: frictionless, a closed site sticks)."""

    fn: float
    s1: float
    s2: float
    speed: float
    tau: float
    un: float
    area: float
    eps: float


class DriveClock(NamedTuple):
    """The step's length ``dt`` [s] and the drive's phase: ``phase_f`` = omega t [rad] at the time of the forces
    (cos_f, sin_f of it) and cos_d, sin_d of it at the time of the displacements."""

    dt: float
    cos_f: float
    sin_f: float
    phase_f: float
    cos_d: float
    sin_d: float


class SiteAccumulators(NamedTuple):
    """The per-site diagnostics' accumulators (app/contact/tables.py): ``sums`` (n, 14), the wave-frame ``bins``
    (groups, n_bins, 8), each site's ``group`` of bins and its wave-phase reference ``phase`` [rad] (NaN: none)."""

    sums: np.ndarray
    bins: np.ndarray
    group: np.ndarray
    phase: np.ndarray


@njit(cache=True, _nrt=False)
def accumulate_site(i, site, clock, acc):
    """Adds one step of site i (``site``: :class:`SiteSample`; ``clock``: :class:`DriveClock`) to the per-site
    diagnostics ``acc`` (:class:`SiteAccumulators`, app/contact/tables.py), the one rule of every tier.
    ``acc.sums`` (n, 14): pressure, closed, stick, slip +e1, slip -e1; while slipping |s1|, |s2|, |s|; the friction
    power per area along e1 and e2 (tau s_k^2 / sqrt(|s|^2 + eps^2), which sum to the law's tau |s|^2 / sqrt(...));
    the first harmonic at the drive frequency of the pressure and of un (cos, sin parts) - each times dt.
    ``acc.bins`` (groups, n_bins, 8): with the site's wave phase known (``acc.phase[i]``: the phase of un's harmonic,
    not NaN), area-weighted, in the bin of the wave phase xi = phase[i] - omega t (0: the crest passes the site;
    positive: the crest has yet to come) of the site's group: area, normal force, area closed, sticking, slipping
    +e1 / -e1, area x |s1|, area x |s2| while slipping - each times dt. The records hold scalars or four arrays:
    passing them costs nothing measurable per site and step (BENCHMARKS.md, the diagnostics' cost)."""
    fn, s1, s2, speed, tau, un, area, eps = site
    dt, cos_f, sin_f, drive_phase_f, cos_d, sin_d = clock
    sums, bins, group, phase = acc
    p = fn / area if fn > 0.0 else 0.0
    sums[i, 10] += dt * p * cos_f
    sums[i, 11] += dt * p * sin_f
    sums[i, 12] += dt * un * cos_d
    sums[i, 13] += dt * un * sin_d
    ph = phase[i]
    b = -1
    g = group[i]
    if ph == ph:                                   # not NaN: the site's wave phase is known
        n_bins = bins.shape[1]
        turns = (ph - drive_phase_f) * (0.5 / math.pi) + 0.5 / n_bins      # bin 0 centred on the crest
        b = min(int((turns - math.floor(turns)) * n_bins), n_bins - 1)
        bins[g, b, 0] += dt * area
    if fn <= 0.0:
        return
    sums[i, 0] += dt * p
    sums[i, 1] += dt
    if b >= 0:
        bins[g, b, 1] += dt * fn
        bins[g, b, 2] += dt * area
    if speed <= eps:
        sums[i, 2] += dt
        if b >= 0:
            bins[g, b, 3] += dt * area
        return
    k = 3 if s1 > 0.0 else 4
    sums[i, k] += dt
    a1, a2 = abs(s1), abs(s2)
    sums[i, 5] += dt * a1
    sums[i, 6] += dt * a2
    sums[i, 7] += dt * speed
    power = dt * tau / math.sqrt(speed * speed + eps * eps)
    sums[i, 8] += power * s1 * s1
    sums[i, 9] += power * s2 * s2
    if b >= 0:
        bins[g, b, k + 1] += dt * area
        bins[g, b, 6] += dt * area * a1
        bins[g, b, 7] += dt * area * a2


@njit(cache=True)
def stick_speed(contacts, c):
    """The slip speed [m/s] at or below which a closed site of contact c counts as sticking: the friction's
    regularisation speed, inf for a frictionless contact."""
    return contacts.eps[c] if contacts.mu[c] > 0.0 else math.inf


@njit(cache=True)
def accumulate_sites(y, v, z, zd, dt, t, omega, sites, contacts, bodies, acc, work):
    """Per-site diagnostics of a state at time t [s] (site displacements ``y`` and velocities ``v``, (n, 3); body
    coordinates and rates), the drive at ``omega`` [rad/s]: :func:`accumulate_site` for every site into ``acc``
    (:class:`SiteAccumulators`), the modal tier's rule (app/reduced/kernel.py) for the FE tier."""
    drive_phase = omega * t
    cos_t, sin_t = math.cos(drive_phase), math.sin(drive_phase)
    clock = DriveClock(dt, cos_t, sin_t, drive_phase, cos_t, sin_t)
    for i in range(sites.contact.size):
        fn, gap, s1, s2, speed = site_force(i, y[i], v[i], z, zd, sites, contacts, bodies, 1.0, 1.0, False, work)
        un = -_dot3(sites.frame[i, 0], y[i])
        c = sites.contact[i]
        tau = 0.0
        if fn > 0.0 and contacts.mu[c] > 0.0:
            tau = _friction_shear(speed, fn / sites.weight[i], contacts.mu[c], contacts.fact[c], contacts.decay[c],
                                  contacts.cap[c])[0]
        accumulate_site(i, SiteSample(fn, s1, s2, speed, tau, un, sites.weight[i], stick_speed(contacts, c)), clock,
                        acc)
