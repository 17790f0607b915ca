"""Compiled time loop of the modal-reduced tier (numba): reduced structure + rigid bodies + contacts.

The FE tier's step (:mod:`app.transient.coupled`) and step control (:mod:`app.transient.control`)
on a small dense system, so that a step costs microseconds instead of a sparse back-substitution
and Python callbacks:

* generalized-alpha on the reduced coordinates q (free ones solved, driven electrode coordinates
  prescribed through their Newmark kinematics, see :mod:`app.reduced.integrator`) and on the rigid
  bodies' translations z; the equations are imposed at the generalized mid-points, contact forces
  evaluated there, as in the FE tier;
* interactions: node contacts (a power-law spring, Hertz with exponent 1.5, plus a clipped damper,
  between an interface node and a body's sphere), rigid-rigid Kelvin-Voigt links, and frictionless
  surface contacts: a facet group's nodes (interface coordinates) each carry a lumped area and
  press with the penalty pressure < k (-g) + c (-dg/dt) > against the body's plane or sphere, the
  gap and normal formed exactly at the node (a sphere's normal turns with the node: its tangent
  includes the p / |d| (I - n n) term);
* Newton with backtracking on the free coordinates and body DOFs, converged when the residual
  norm is below ``rtol`` times the step's force scale (plus round-off), as the FE tier's SNES;
* step sizes by contact state: ``open``, ``closed``, ``change`` with event refinement (a step that
  changes the contact set while dt > change is retried with a quarter of it), approach to a
  predicted closure, cut-back by halving on Newton failure, growth back after cut-backs; below
  ``min`` the loop stops with a failure code (the driver turns it into NumericalFailure).

The loop runs until the end time, until the output buffer is full, or (when the driver asks for
field output) right after the first accepted step at or after ``fstate[F_OUTPUT]``; the driver then
writes the rows, expands the fields, checkpoints and calls again. Every quantity that the next
call needs is in the state arrays (q, v, a, z, zd, zdd, istate, fstate); what else the loop keeps
(the closed flags, the predicted closure, the K_eff^-1 of each step size) is a function of them,
recomputed at the start of every call, so where a run is split into calls does not change it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# integer controller state slots
I_STEPS, I_ATTEMPTS, I_CUTBACKS, I_REFINEMENTS, I_NEWTON, I_CHANGED = range(6)
N_ISTATE = 6
# float controller state slots: time [s], step cap after cut-backs [s], next field output [s]
F_TIME, F_CAP, F_OUTPUT = range(3)
N_FSTATE = 3
# return codes
DONE, BUFFER_FULL, STEP_FAILED, FIELD_OUTPUT = 0, 1, 2, 3
CACHE_SLOTS = 24        # K_eff^-1 kept for this many step sizes
MAX_NEWTON = 20
NEWTON_RTOL = 1e-10
NEWTON_STOL = 1e-14
EPS = 2.220446049250313e-16


@njit(cache=True, error_model="numpy")
def _drive(t, amp, phase, omega, cosine, out_q, out_v, out_a):
    """Values of the prescribed coordinates: A sin(w t + phase) from rest, A cos(...) after a
    harmonic start (derivatives used for the initial state only)."""
    for p in range(amp.size):
        arg = omega * t + phase[p]
        if cosine:
            out_q[p] = amp[p] * np.cos(arg)
            out_v[p] = -amp[p] * omega * np.sin(arg)
            out_a[p] = -amp[p] * omega * omega * np.cos(arg)
        else:
            out_q[p] = amp[p] * np.sin(arg)
            out_v[p] = amp[p] * omega * np.cos(arg)
            out_a[p] = -amp[p] * omega * omega * np.sin(arg)


@njit(cache=True, error_model="numpy")
def _node_force(i, q_mid, v_mid, z_mid, zd_mid, nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c,
                nc_exp, gdim):
    """(F >= 0, dF/d delta, dF/d rate, delta) of node contact i at the mid-point state."""
    gap = nc_offset[i]
    rate = 0.0
    b = nc_body[i]
    for k in range(gdim):
        n = nc_normal[i, k]
        if n == 0.0:
            continue
        j = nc_coord[i, k]
        u = q_mid[j] if j >= 0 else 0.0
        w = v_mid[j] if j >= 0 else 0.0
        gap += n * (u - (z_mid[b * gdim + k] - nc_ref[i, k]))
        rate += n * (w - zd_mid[b * gdim + k])
    delta = -gap
    delta_rate = -rate
    if delta <= 0.0:
        return 0.0, 0.0, 0.0, delta
    power = delta ** nc_exp[i]
    f = nc_k[i] * power + nc_c[i] * delta_rate
    if f <= 0.0:
        return 0.0, 0.0, 0.0, delta
    return f, nc_exp[i] * nc_k[i] * power / delta, nc_c[i], delta


@njit(cache=True, error_model="numpy")
def _surface_node(i, q_mid, v_mid, z_mid, zd_mid, sn_contact, sn_coord, sn_rel, sc_body, sc_kind, sc_normal,
                  sc_radius, sc_ref, gdim, d, w, n):
    """Gap [m], gap rate [m/s] and distance |d| [m] (sphere; 1 for a plane) of surface node i at a
    state; fills d (node relative to the obstacle), w (relative velocity) and the unit normal n.

    The node's position relative to the obstacle is formed as (reference difference, stored once)
    + (u - body displacement), never from absolute positions, as the FE tier does (the gap of a
    stiff penalty must not carry round-off of |x|). A sphere with a pole p stores e0 = x - (centre +
    R p) and forms g = (|e|^2 + 2 R p.e) / (|R p + e| + R), the cancellation-free |d| - R."""
    c = sn_contact[i]
    b = sc_body[c]
    for k in range(gdim):
        j = sn_coord[i, k]
        u = q_mid[j] if j >= 0 else 0.0
        uv = v_mid[j] if j >= 0 else 0.0
        d[k] = sn_rel[i, k] + (u - (z_mid[b * gdim + k] - sc_ref[c, k]))
        w[k] = uv - zd_mid[b * gdim + k]
    if sc_kind[c] == 0:                                 # plane: fixed normal
        gap = 0.0
        rate = 0.0
        for k in range(gdim):
            n[k] = sc_normal[c, k]
            gap += n[k] * d[k]
            rate += n[k] * w[k]
        return gap, rate, 1.0
    radius = sc_radius[c]
    has_pole = False
    for k in range(gdim):
        has_pole = has_pole or sc_normal[c, k] != 0.0
    ee = 0.0
    pe = 0.0
    if has_pole:                                        # d holds e = y - (centre + R p)
        for k in range(gdim):
            ee += d[k] * d[k]
            pe += sc_normal[c, k] * d[k]
            d[k] = radius * sc_normal[c, k] + d[k]
    dist = 0.0
    for k in range(gdim):
        dist += d[k] * d[k]
    dist = np.sqrt(dist)
    gap = (ee + 2.0 * radius * pe) / (dist + radius) if has_pole else dist - radius
    rate = 0.0
    for k in range(gdim):
        n[k] = d[k] / dist
        rate += n[k] * w[k]
    return gap, rate, dist


@njit(cache=True, error_model="numpy")
def _point_force(i, z_mid, zd_mid, pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c, gdim):
    lo, up = pc_lower[i], pc_upper[i]
    delta = pc_touch[i]
    rate = 0.0
    for k in range(gdim):
        delta -= pc_dir[i, k] * (z_mid[up * gdim + k] - z_mid[lo * gdim + k])
        rate -= pc_dir[i, k] * (zd_mid[up * gdim + k] - zd_mid[lo * gdim + k])
    if delta <= 0.0:
        return 0.0, 0.0, 0.0, delta
    f = pc_k[i] * delta + pc_c[i] * rate
    if f <= 0.0:
        return 0.0, 0.0, 0.0, delta
    return f, pc_k[i], pc_c[i], delta


@njit(cache=True, error_model="numpy")
def _surface_terms(q_mid, v_mid, z_mid, zd_mid, s, w_f, c_vel, G_SS, gdim, sn_contact, sn_coord, sn_rel, sn_area,
                   sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref, F, J, Kss, want_jacobian, sforce):
    """Residual (and tangent) terms of the surface contacts' nodes, the node-contact pattern with a
    full gdim x gdim block: node i pushes with F_i = A_i p n on the structure and -F_i on the body,
    p = < k (-g) + c (-dg/dt) > while g < 0. D = dF_i / d(relative-position increment over the
    step) = A_i w_f [n (x) (-k n - c P w / r) + p P / r - c_vel c n (x) n] with P = I - n n, w the
    relative velocity and r = |d| (a plane: the curvature terms vanish)."""
    for c in range(sc_k.size):
        for k in range(gdim):
            sforce[c, k] = 0.0
    if sn_contact.size == 0:
        return
    d = np.empty(gdim)
    w = np.empty(gdim)
    n = np.empty(gdim)
    D = np.empty((gdim, gdim))
    for i in range(sn_contact.size):
        c = sn_contact[i]
        b = sc_body[c]
        gap, rate, dist = _surface_node(i, q_mid, v_mid, z_mid, zd_mid, sn_contact, sn_coord, sn_rel, sc_body,
                                        sc_kind, sc_normal, sc_radius, sc_ref, gdim, d, w, n)
        if gap >= 0.0:
            continue
        pressure = -sc_k[c] * gap - sc_c[c] * rate
        if pressure <= 0.0:
            continue
        area = sn_area[i]
        for k in range(gdim):
            f = area * pressure * n[k]
            j = sn_coord[i, k]
            if j >= 0:
                F[j] -= f
            F[s + b * gdim + k] += f
            sforce[c, k] -= f
        if not want_jacobian:
            continue
        curved = sc_kind[c] != 0
        for k in range(gdim):
            for kk in range(gdim):
                nn = n[k] * n[kk]
                value = -(sc_k[c] + sc_c[c] * c_vel) * nn
                if curved:
                    projector = (1.0 if k == kk else 0.0) - nn
                    value += (-sc_c[c] * n[k] * (w[kk] - rate * n[kk]) + pressure * projector) / dist
                D[k, kk] = area * w_f * value
        # rc_S = -F_i, r_z = +F_i; the relative position grows with u and falls with z
        for k in range(gdim):
            row_q = sn_coord[i, k]
            row_z = s + b * gdim + k
            for kk in range(gdim):
                col_q = sn_coord[i, kk]
                col_z = s + b * gdim + kk
                coeff = D[k, kk]
                if row_q >= 0:
                    if col_q >= 0:
                        Kss[row_q, col_q] -= coeff
                    J[row_q, col_z] += coeff
                if col_q >= 0:
                    for kk2 in range(s):
                        J[row_z, kk2] -= coeff * G_SS[col_q, kk2]      # D (-G)
                J[row_z, col_z] -= coeff


@njit(cache=True, error_model="numpy")
def _contact_system(g, dz, uS0, G_SS, qS0, vS0, aS0, z0, zd0, zdd0, dt, beta, gamma, alpha_m, alpha_f,
                    body_mass, body_force, zfree, gdim, nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c,
                    nc_exp, pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel, sn_area,
                    sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref, F, J, want_jacobian, forces, sforce):
    """Condensed residual on (g, dz) and, optionally, its Jacobian; contact forces into ``forces``.

    The structure's equations are linear, so for contact residuals g on the interface coordinates
    its increments are dq = (predictor + w) - G g (``uS0`` = the interface part of predictor + w,
    ``G_SS`` = the interface block of K_eff^-1, both formed once per step / per dt). Newton then
    runs on g and the body increments dz only: F_g = rc_S(dq_S(g), dz) - g, F_z = r_z(dq_S, dz),
    the FE tier's condensed system (app.transient.coupled) on a dense model. ``sforce`` gets the
    force of each surface contact on its body [N]."""
    s = g.size
    m = dz.size
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    w_f = 1.0 - alpha_f
    dqS = uS0 - G_SS @ g
    aS1 = (dqS - dt * vS0) * c_acc - (1.0 / (2.0 * beta) - 1.0) * aS0
    vS1 = vS0 + dt * ((1.0 - gamma) * aS0 + gamma * aS1)
    q_mid = qS0 + w_f * dqS
    v_mid = w_f * vS1 + alpha_f * vS0
    zdd1 = (dz - dt * zd0) * c_acc - (1.0 / (2.0 * beta) - 1.0) * zdd0
    zd1 = zd0 + dt * ((1.0 - gamma) * zdd0 + gamma * zdd1)
    z_mid = z0 + w_f * dz
    zd_mid = w_f * zd1 + alpha_f * zd0
    for k in range(s):
        F[k] = -g[k]
    for j in range(m):
        F[s + j] = body_mass[j // gdim] * ((1.0 - alpha_m) * zdd1[j] + alpha_m * zdd0[j]) - body_force[j]
    if want_jacobian:
        for a in range(s + m):
            for b in range(s + m):
                J[a, b] = 0.0
        for k in range(s):
            J[k, k] = -1.0
        for j in range(m):
            J[s + j, s + j] = (1.0 - alpha_m) * c_acc * body_mass[j // gdim]
    Kss = np.zeros((s, s))
    for i in range(nc_k.size):
        f, df, dfr, _ = _node_force(i, q_mid, v_mid, z_mid, zd_mid, nc_coord, nc_normal, nc_offset, nc_ref,
                                    nc_body, nc_k, nc_c, nc_exp, gdim)
        forces[i] = f
        b = nc_body[i]
        for k in range(gdim):
            n = nc_normal[i, k]
            j = nc_coord[i, k]
            if j >= 0:
                F[j] -= f * n
            F[s + b * gdim + k] += f * n
        if want_jacobian and f > 0.0:
            slope = w_f * (df + dfr * c_vel)          # d F / d (delta increment over the step)
            for k in range(gdim):
                row_q = nc_coord[i, k]
                row_z = s + b * gdim + k
                for kk in range(gdim):
                    col_q = nc_coord[i, kk]
                    col_z = s + b * gdim + kk
                    coeff = slope * nc_normal[i, k] * nc_normal[i, kk]
                    # rc_S = -F n, r_z = +F n; d delta / d u = -n, d delta / d z = +n
                    if row_q >= 0:
                        if col_q >= 0:
                            Kss[row_q, col_q] += coeff
                        J[row_q, col_z] -= coeff
                    if col_q >= 0:
                        for kk2 in range(s):
                            J[row_z, kk2] += coeff * G_SS[col_q, kk2]      # (-coeff) * (-G)
                    J[row_z, col_z] += coeff
    _surface_terms(q_mid, v_mid, z_mid, zd_mid, s, w_f, c_vel, G_SS, gdim, sn_contact, sn_coord, sn_rel, sn_area,
                   sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref, F, J, Kss, want_jacobian, sforce)
    for c in range(sc_k.size):
        forces[nc_k.size + pc_k.size + c] = np.sqrt(np.sum(sforce[c] * sforce[c]))
    if want_jacobian:
        KG = Kss @ G_SS
        for a in range(s):
            for b in range(s):
                J[a, b] -= KG[a, b]
    base = nc_k.size
    for i in range(pc_k.size):
        f, df, dfr, _ = _point_force(i, z_mid, zd_mid, pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c, gdim)
        forces[base + i] = f
        lo, up = pc_lower[i], pc_upper[i]
        for k in range(gdim):
            F[s + up * gdim + k] -= f * pc_dir[i, k]
            F[s + lo * gdim + k] += f * pc_dir[i, k]
        if want_jacobian and f > 0.0:
            slope = w_f * (df + dfr * c_vel)
            for k in range(gdim):
                for kk in range(gdim):
                    coeff = slope * pc_dir[i, k] * pc_dir[i, kk]
                    J[s + up * gdim + k, s + up * gdim + kk] += coeff
                    J[s + lo * gdim + k, s + lo * gdim + kk] += coeff
                    J[s + up * gdim + k, s + lo * gdim + kk] -= coeff
                    J[s + lo * gdim + k, s + up * gdim + kk] -= coeff
    for j in range(m):
        if not zfree[j]:
            F[s + j] = 0.0
            if want_jacobian:
                for k in range(s + m):
                    J[s + j, k] = 0.0
                    J[k, s + j] = 0.0
                J[s + j, s + j] = 1.0
    return zdd1, zd1


@njit(cache=True, error_model="numpy")
def _status(q, v, z, zd, gdim, nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp, pc_lower,
            pc_upper, pc_dir, pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel, sc_body, sc_kind, sc_normal,
            sc_radius, sc_k, sc_ref, closed):
    """Closed flags of every contact at an end-of-step state and the earliest predicted closure [s]."""
    closure = np.inf
    for i in range(nc_k.size):
        gap = nc_offset[i]
        rate = 0.0
        b = nc_body[i]
        for k in range(gdim):
            n = nc_normal[i, k]
            j = nc_coord[i, k]
            u = q[j] if j >= 0 else 0.0
            w = v[j] if j >= 0 else 0.0
            gap += n * (u - (z[b * gdim + k] - nc_ref[i, k]))
            rate += n * (w - zd[b * gdim + k])
        closed[i] = gap < 0.0
        if gap >= 0.0 and rate < 0.0:
            closure = min(closure, gap / -rate)
    base = nc_k.size
    for i in range(pc_k.size):
        lo, up = pc_lower[i], pc_upper[i]
        delta = pc_touch[i]
        rate = 0.0
        for k in range(gdim):
            delta -= pc_dir[i, k] * (z[up * gdim + k] - z[lo * gdim + k])
            rate -= pc_dir[i, k] * (zd[up * gdim + k] - zd[lo * gdim + k])
        closed[base + i] = delta > 0.0
        if delta <= 0.0 and rate > 0.0:
            closure = min(closure, -delta / rate)
    # a surface contact is closed while any of its nodes penetrates (where its force acts)
    base = nc_k.size + pc_k.size
    for c in range(sc_k.size):
        closed[base + c] = False
    d = np.empty(gdim)
    w = np.empty(gdim)
    n = np.empty(gdim)
    for i in range(sn_contact.size):
        gap, rate, _ = _surface_node(i, q, v, z, zd, sn_contact, sn_coord, sn_rel, sc_body, sc_kind, sc_normal,
                                     sc_radius, sc_ref, gdim, d, w, n)
        if gap < 0.0:
            closed[base + sn_contact[i]] = True
        elif rate < 0.0:
            closure = min(closure, gap / -rate)
    return closure


@njit(cache=True, error_model="numpy")
def _snap(level, dt):
    """Largest level / 2^k not above dt (dt > 0)."""
    if dt >= level:
        return level
    k = np.ceil(np.log2(level / dt) - 1e-12)
    return level / 2.0 ** k


@njit(cache=True, error_model="numpy")
def _effective_inverse(K, M, C, free_q, dt, beta, gamma, alpha_m, alpha_f):
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    nf = free_q.size
    A = np.empty((nf, nf))
    for i in range(nf):
        for k in range(nf):
            a, b = free_q[i], free_q[k]
            A[i, k] = (1.0 - alpha_m) * c_acc * M[a, b] + (1.0 - alpha_f) * c_vel * C[a, b] + (1.0 - alpha_f) * K[a, b]
    return np.linalg.inv(A)


@njit(cache=True, error_model="numpy")
def run(t_end, q, v, a, z, zd, zdd, closed, istate, fstate,
        K, M, C, fq, free_q, pres_q, drive_amp, drive_phase, omega, cosine, body_mass, body_force, zfree, gdim,
        nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp,
        pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c,
        sn_contact, sn_coord, sn_rel, sn_area, sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref,
        beta, gamma, alpha_m, alpha_f, open_s, closed_s, change_s, min_s, growth,
        sample_rows, out_time, out_dt, out_samples, out_drive, out_z, out_zd, out_force, out_closed, out_surface,
        cache_dt=None, cache_inv=None):
    """Advance the state arrays (in place) to ``t_end``, until the output buffers are full or, if
    ``fstate`` has the slot F_OUTPUT, until the first accepted step at t >= fstate[F_OUTPUT] (code
    FIELD_OUTPUT; a 2-slot fstate never stops for output). Returns (code, rows written). One output
    row per accepted step: time, dt, ``sample_rows @ q``, the prescribed coordinates, body positions
    and velocities, contact forces [N] (magnitudes: node contacts, links, then surface contacts) and
    closed flags, and the force vector of each surface contact on its body (``out_surface``, gdim
    columns per surface contact).

    Surface contacts: ``sn_*`` per node (its contact, interface coordinate per axis or -1 if held,
    reference relative position [m], lumped area [m^2]), ``sc_*`` per contact (body, shape 0 plane /
    1 sphere, plane normal or sphere pole (zeros: none), radius [m], penalty [Pa/m], damping
    [Pa s/m], the body's reference position [m]).

    The interface coordinates (those the node and surface contacts act on) must be the first free
    coordinates, ``free_q[:s] == arange(s)`` (the Craig-Bampton order).

    ``cache_dt`` (CACHE_SLOTS, -1 = empty) and ``cache_inv`` (CACHE_SLOTS x n_free x n_free), if
    given, keep K_eff^-1 of the step sizes used from one call to the next (a run split into many
    calls for checkpoints and field outputs then forms each once); they are a function of dt
    alone, so they change the cost of a call, never its result."""
    nf = free_q.size
    m = z.size
    s = 0
    for i in range(nc_coord.shape[0]):
        for k in range(gdim):
            s = max(s, nc_coord[i, k] + 1)
    for i in range(sn_coord.shape[0]):
        for k in range(gdim):
            s = max(s, sn_coord[i, k] + 1)
    n_contacts = nc_k.size + pc_k.size + sc_k.size
    sforce = np.zeros((sc_k.size, gdim))
    F = np.zeros(s + m)
    F_try = np.zeros(s + m)
    J = np.zeros((s + m, s + m))
    forces = np.zeros(max(n_contacts, 1))
    new_closed = np.zeros(max(n_contacts, 1), dtype=np.bool_)
    pq = np.zeros(pres_q.size)
    pv = np.zeros(pres_q.size)
    pa = np.zeros(pres_q.size)
    # K_eff^-1 of the free coordinates for the few step sizes a run uses
    slots = CACHE_SLOTS
    if cache_dt is None:
        cache_dt = np.full(slots, -1.0)
    if cache_inv is None:
        cache_inv = np.zeros((slots, nf, nf))
    cache_cols = np.zeros((slots, nf, s))           # K_eff^-1 E: the columns of the interface coordinates
    cache_block = np.zeros((slots, s, s))           # their interface rows, G_SS
    cache_next = 0
    for c in range(slots):                          # entries kept from an earlier call
        if cache_dt[c] > 0:
            cache_cols[c] = np.ascontiguousarray(cache_inv[c][:, :s])
            cache_block[c] = np.ascontiguousarray(cache_inv[c][:s, :s])
            cache_next = (c + 1) % slots
    rows = 0
    capacity = out_time.size
    t = fstate[F_TIME]
    closure = _status(q, v, z, zd, gdim, nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp,
                      pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel, sc_body,
                      sc_kind, sc_normal, sc_radius, sc_k, sc_ref, closed)
    load_scale = np.sqrt(np.sum(fq * fq) + np.sum(body_force * body_force))
    body_mass_dofs = np.zeros(m)
    for j in range(m):
        body_mass_dofs[j] = body_mass[j // gdim] if zfree[j] else 0.0
    next_output = fstate[F_OUTPUT] if fstate.size > F_OUTPUT else np.inf
    while t < t_end * (1.0 - 1e-12):
        if rows >= capacity:
            fstate[F_TIME] = t
            return BUFFER_FULL, rows
        any_closed = False
        for i in range(n_contacts):
            any_closed = any_closed or closed[i]
        if istate[I_CHANGED]:
            dt = change_s
        elif any_closed:
            dt = closed_s
        else:
            dt = open_s
            if closure < dt:
                dt = max(change_s, _snap(open_s, max(0.5 * closure, 1e-300)))
        if dt > fstate[F_CAP]:
            dt = _snap(dt, fstate[F_CAP])
        while True:
            remainder = t_end - t
            dt_try = dt if remainder >= dt * (1.0 - 1e-9) else remainder
            istate[I_ATTEMPTS] += 1
            t1 = t + dt_try
            slot = -1
            for c in range(slots):
                if cache_dt[c] > 0 and abs(cache_dt[c] - dt_try) <= 1e-12 * dt_try:
                    slot = c
            if slot < 0:
                slot = cache_next
                cache_next = (cache_next + 1) % slots
                cache_dt[slot] = dt_try
                cache_inv[slot] = _effective_inverse(K, M, C, free_q, dt_try, beta, gamma, alpha_m, alpha_f)
                cache_cols[slot] = np.ascontiguousarray(cache_inv[slot][:, :s])
                cache_block[slot] = np.ascontiguousarray(cache_inv[slot][:s, :s])
            A_inv = cache_inv[slot]
            G_cols = cache_cols[slot]
            G_SS = cache_block[slot]
            c_acc = 1.0 / (beta * dt_try * dt_try)
            _drive(t1, drive_amp, drive_phase, omega, cosine, pq, pv, pa)
            # predictor increments; the structure's residual there without contact, and w = -K_eff^-1 r0
            dq = dt_try * v + 0.5 * dt_try * dt_try * a
            for p in range(pres_q.size):
                dq[pres_q[p]] = pq[p] - q[pres_q[p]]
            a1 = (dq - dt_try * v) * c_acc - (1.0 / (2.0 * beta) - 1.0) * a
            v1 = v + dt_try * ((1.0 - gamma) * a + gamma * a1)
            inertia_term = M @ ((1.0 - alpha_m) * a1 + alpha_m * a)
            damping_term = C @ ((1.0 - alpha_f) * v1 + alpha_f * v)
            stiffness_term = K @ (q + (1.0 - alpha_f) * dq)
            r0 = inertia_term + damping_term + stiffness_term - fq
            r0F = np.empty(nf)
            for i in range(nf):
                r0F[i] = r0[free_q[i]]
            w = -(A_inv @ r0F)
            uS0 = dq[:s] + w[:s]
            dz = dt_try * zd + 0.5 * dt_try * dt_try * zdd
            for j in range(m):
                if not zfree[j]:
                    dz[j] = 0.0
            g = np.zeros(s)
            # tolerance: rtol times the forces the step balances (the FE tier's scale), never below
            # their round-off (the rigid inertia is formed from increments / (beta dt^2))
            scale = load_scale + np.sqrt(np.sum(inertia_term**2) + np.sum(damping_term**2)
                                         + np.sum(stiffness_term**2))
            # the body accelerations come from (dz - dt zd) c_acc: its round-off is eps |zd| c_acc dt
            rigid_inertia = np.sqrt(np.sum((body_mass_dofs * dt_try * zd * c_acc) ** 2)
                                    + np.sum((body_mass_dofs * zdd) ** 2))
            atol = NEWTON_RTOL * scale + 10.0 * EPS * (scale + rigid_inertia) + 1e-300
            converged = False
            iterations = 0
            zdd1, zd1 = _contact_system(g, dz, uS0, G_SS, q[:s], v[:s], a[:s], z, zd, zdd, dt_try, beta, gamma,
                                        alpha_m, alpha_f, body_mass, body_force, zfree, gdim, nc_coord, nc_normal,
                                        nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp, pc_lower, pc_upper, pc_dir,
                                        pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel, sn_area, sc_body,
                                        sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref, F, J, True, forces, sforce)
            norm = np.sqrt(np.sum(F * F))
            # ... nor below the round-off of the contact forces themselves: a body in free rigid
            # translation balances nothing else (a rod striking a wall: scale ~1e-6 N against
            # 6e5 N of contact force, whose balance rounds at ~1e-10 N)
            atol += 10.0 * EPS * norm
            while iterations < MAX_NEWTON and np.isfinite(norm):
                if norm <= atol:
                    converged = True
                    break
                step = np.linalg.solve(J, -F)
                lam = 1.0
                accepted = False
                for _ in range(12):                     # backtracking: accept a decrease
                    g_try = g + lam * step[:s]
                    dz_try = dz + lam * step[s:]
                    _contact_system(g_try, dz_try, uS0, G_SS, q[:s], v[:s], a[:s], z, zd, zdd, dt_try, beta, gamma,
                                    alpha_m, alpha_f, body_mass, body_force, zfree, gdim, nc_coord, nc_normal,
                                    nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp, pc_lower, pc_upper, pc_dir,
                                    pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel, sn_area, sc_body, sc_kind,
                                    sc_normal, sc_radius, sc_k, sc_c, sc_ref, F_try, J, False, forces, sforce)
                    norm_try = np.sqrt(np.sum(F_try * F_try))
                    if norm_try <= (1.0 - 1e-4 * lam) * norm or norm_try <= atol:
                        accepted = True
                        break
                    lam *= 0.5
                iterations += 1
                if not accepted:
                    break
                small = lam * np.sqrt(np.sum(step * step)) <= NEWTON_STOL * (
                    np.sqrt(np.sum(g * g)) + np.sqrt(np.sum(dz * dz)) + 1e-300)
                g, dz = g_try, dz_try
                zdd1, zd1 = _contact_system(g, dz, uS0, G_SS, q[:s], v[:s], a[:s], z, zd, zdd, dt_try, beta, gamma,
                                            alpha_m, alpha_f, body_mass, body_force, zfree, gdim, nc_coord,
                                            nc_normal, nc_offset, nc_ref, nc_body, nc_k, nc_c, nc_exp, pc_lower,
                                            pc_upper, pc_dir, pc_touch, pc_k, pc_c, sn_contact, sn_coord, sn_rel,
                                            sn_area, sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_c, sc_ref, F, J,
                                            True, forces, sforce)
                norm = np.sqrt(np.sum(F * F))
                if small and norm <= 1e3 * atol:
                    converged = True
                    break
            istate[I_NEWTON] += max(iterations, 1)
            if not converged:
                istate[I_CUTBACKS] += 1
                dt = 0.5 * dt_try
                if dt < min_s:
                    fstate[F_TIME] = t
                    return STEP_FAILED, rows
                fstate[F_CAP] = dt
                continue
            # the structure's increments for the converged contact residuals
            corr = w - G_cols @ g
            for i in range(nf):
                dq[free_q[i]] += corr[i]
            a1 = (dq - dt_try * v) * c_acc - (1.0 / (2.0 * beta) - 1.0) * a
            v1 = v + dt_try * ((1.0 - gamma) * a + gamma * a1)
            q1 = q + dq
            z1 = z + dz
            new_closure = _status(q1, v1, z1, zd1, gdim, nc_coord, nc_normal, nc_offset, nc_ref, nc_body, nc_k,
                                  nc_c, nc_exp, pc_lower, pc_upper, pc_dir, pc_touch, pc_k, pc_c, sn_contact,
                                  sn_coord, sn_rel, sc_body, sc_kind, sc_normal, sc_radius, sc_k, sc_ref, new_closed)
            changed = False
            for i in range(n_contacts):
                changed = changed or (new_closed[i] != closed[i])
            if changed and dt_try > change_s * (1.0 + 1e-9):
                istate[I_REFINEMENTS] += 1
                dt = max(0.25 * dt_try, change_s)
                continue
            break
        # accepted: export, shift, adapt dt
        out_time[rows] = t1
        out_dt[rows] = dt_try
        out_samples[rows, :] = sample_rows @ q1
        out_drive[rows, :] = pq
        out_z[rows, :] = z1
        out_zd[rows, :] = zd1
        for i in range(n_contacts):
            out_force[rows, i] = forces[i]
            out_closed[rows, i] = new_closed[i]
        for c in range(sc_k.size):
            for k in range(gdim):
                out_surface[rows, c * gdim + k] = sforce[c, k]
        rows += 1
        q[:] = q1
        v[:] = v1
        a[:] = a1
        z[:] = z1
        zd[:] = zd1
        zdd[:] = zdd1
        for i in range(n_contacts):
            closed[i] = new_closed[i]
        closure = new_closure
        istate[I_CHANGED] = 1 if changed else 0
        istate[I_STEPS] += 1
        t = t1
        if fstate[F_CAP] < np.inf:
            fstate[F_CAP] = dt_try * growth
            if fstate[F_CAP] >= max(open_s, closed_s):
                fstate[F_CAP] = np.inf
        if t >= next_output:                    # the driver expands the fields of this state
            fstate[F_TIME] = t
            return FIELD_OUTPUT, rows
    fstate[F_TIME] = t
    return DONE, rows
