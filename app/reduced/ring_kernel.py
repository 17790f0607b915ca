"""Compiled time loop of a reduced stator pressing a rigid cone rotor (the motor in the modal tier).

The stator is a Craig-Bampton model whose interface is ``n_points`` nodes of the contact band (three
displacement DOFs each, the first coordinates of q), driven through its electrode coordinates. The rotor
is a rigid body of revolution about the z axis: an axial offset dz [m] from its reference height and a
spin rate Omega [rad/s] (free, or prescribed). Because the rotor is a body of revolution its angle
changes no gap, only the slip velocity, so the angle itself is integrated alongside and never enters a
force.

Per band node i (reference position on the cone, fixed frame e_r, e_theta, e_z of its azimuth; small
displacements, so the frame is the reference one):

* gap g = g0 + n.u + sin(alpha) dz, with n = cos(alpha) e_r - sin(alpha) e_z the cone's outward normal
  (from the rotor towards the stator) and g0 the node's geometric gap at the reference height;
* normal force F_n = k A (-g) for g < 0 (penalty k [Pa/m] times the node's share A of the band);
* slip of the stator node over the rotor in the tangent plane (e_theta, t_m = sin(alpha) e_r +
  cos(alpha) e_z): s_theta = e_theta.v - Omega rho, s_m = t_m.v - dz' cos(alpha);
* friction on the stator f_t = -min(mu(|s|) F_n, tau_max A) s / sqrt(|s|^2 + eps^2) (the FE tier's
  regularised Coulomb law, forms/contact.py), mu(|s|) = mu_d (1 + (FACT - 1) exp(-DC |s|));
* the rotor takes the opposite force: axial F_n sin(alpha) - f_m cos(alpha), torque -rho f_theta.

Time scheme: Newmark (beta, gamma; the paper's 0.25 / 0.5) on the stator's free coordinates (driven
electrode coordinates through their Newmark kinematics, as :mod:`app.reduced.integrator`), on dz and on
the spin. With K_eff^-1 of the free coordinates formed once per step size (by the driver), the
structure is condensed onto the interface: u_B = w_B + G f(u_B, dz, Omega), and Newton runs on the
interface displacements of the nodes in contact plus dz and Omega (a node out of contact follows
from the others without a solve). A step whose Newton fails is retried as two half steps, down to
``max_level`` halvings (cut-back, never an abort); the driver calls this loop one drive period at a
time, so the loop carries its whole state in its arguments.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_NEWTON = 40
#: scales of the Newton unknowns in the damping test: interface displacements and dz [m], spin [rad/s]
UNKNOWN_SCALE_M = 1e-12
SPIN_SCALE_RAD_PER_S = 1e-4
#: a Newton iteration whose damping finds no descent is accepted within this factor of the tolerances
ROUND_OFF_FACTOR = 1e3
#: the penalty's kink at first touch is rounded over this penetration [m] (a few % of the static penetration)
ROUNDING_M = 1e-9
DEBUG = False          # print Newton iterations (with NUMBA_DISABLE_JIT=1 only)
# per-step output columns
(C_TIME, C_DZ, C_DZ_RATE, C_SPIN, C_ANGLE, C_NORMAL, C_AXIAL, C_TORQUE, C_DRIVE_SPEED, C_ACTIVE,
 C_E_EL, C_E_DAMP, C_E_FRIC, C_E_OUT, C_E_STORED, C_NEWTON, C_E_REACTION, C_E_CONTACT, C_E_ROTOR,
 C_E_PENALTY) = range(20)
N_COLUMNS = 20
# integer state slots
I_STEPS, I_NEWTON, I_CUTBACKS, I_FAILED = range(4)
N_ISTATE = 4
# point states
SEPARATED, STICK, FORWARD_SLIP, BACKWARD_SLIP = 0, 1, 2, 3


@njit(cache=True, error_model="numpy")
def _drive(t, amp, phase, omega, cosine, out):
    for p in range(amp.size):
        arg = omega * t + phase[p]
        out[p] = amp[p] * (np.cos(arg) if cosine else np.sin(arg))


@njit(cache=True, error_model="numpy")
def _penalty(pen, kA):
    """Normal force [N], its derivative [N/m] and stored energy [J] for a penetration pen > 0: the linear
    penalty kA pen with its kink at first touch rounded over ROUNDING_M (C^1: Newton does not cycle when a
    node opens and closes within a step); the force is kA (pen - ROUNDING_M / 2) beyond it."""
    d0 = ROUNDING_M
    if pen < d0:
        return kA * pen * pen / (2.0 * d0), kA * pen / d0, kA * pen * pen * pen / (6.0 * d0)
    return kA * (pen - 0.5 * d0), kA, kA * (0.5 * pen * pen - 0.5 * d0 * pen + d0 * d0 / 6.0)


@njit(cache=True, error_model="numpy")
def _point_force(i, u, v, dz, dz_rate, spin, frame, g0, rho, area, sin_a, cos_a, k, mu_d, fact, decay, tau_cap,
                 eps, cv, f, D, dfdz, dfds):
    """Force on the stator node i (global components into f[3]) and, if D is not empty, its
    derivatives: D = df/du (3x3, velocity terms through cv = dv/du), dfdz = df/d(dz) (incl. the
    rate through cv), dfds = df/dOmega. Returns (normal force, slip theta, slip m)."""
    n = frame[i, 0]
    e_t = frame[i, 1]
    t_m = frame[i, 2]
    gap = g0[i] + sin_a * dz
    for c in range(3):
        gap += n[c] * u[c]
    for c in range(3):
        f[c] = 0.0
    s_t = -spin * rho[i]
    s_m = -dz_rate * cos_a
    for c in range(3):
        s_t += e_t[c] * v[c]
        s_m += t_m[c] * v[c]
    if gap >= 0.0:
        if D.shape[0]:
            for r in range(3):
                dfdz[r] = 0.0
                dfds[r] = 0.0
                for c in range(3):
                    D[r, c] = 0.0
        return 0.0, s_t, s_m
    kA = k * area[i]
    fn, kp, _ = _penalty(-gap, kA)
    speed2 = s_t * s_t + s_m * s_m
    speed = np.sqrt(speed2 + 1e-30)
    r_eps = np.sqrt(speed2 + eps * eps)
    mu = mu_d * (1.0 + (fact - 1.0) * np.exp(-decay * speed))
    capped = mu * fn > tau_cap * area[i]
    shear = tau_cap * area[i] if capped else mu * fn
    ft_t = -shear * s_t / r_eps
    ft_m = -shear * s_m / r_eps
    for c in range(3):
        f[c] = fn * n[c] + ft_t * e_t[c] + ft_m * t_m[c]
    if D.shape[0]:
        # d shear / d fn, d shear / d |s|
        ds_dfn = 0.0 if capped else mu
        dmu_dspeed = -mu_d * (fact - 1.0) * decay * np.exp(-decay * speed)
        ds_dspeed = 0.0 if capped else dmu_dspeed * fn
        # d(ft)/d(s) (2x2): -shear (I / r - s s^T / r^3) - s / r * ds/d|s| * s^T / |s|
        r3 = r_eps * r_eps * r_eps
        a_tt = -shear * (1.0 / r_eps - s_t * s_t / r3) - s_t / r_eps * ds_dspeed * s_t / speed
        a_tm = -shear * (-s_t * s_m / r3) - s_t / r_eps * ds_dspeed * s_m / speed
        a_mt = -shear * (-s_m * s_t / r3) - s_m / r_eps * ds_dspeed * s_t / speed
        a_mm = -shear * (1.0 / r_eps - s_m * s_m / r3) - s_m / r_eps * ds_dspeed * s_m / speed
        # d(ft)/d(fn)
        b_t = -ds_dfn * s_t / r_eps
        b_m = -ds_dfn * s_m / r_eps
        for r in range(3):
            # fn part: d fn / du = -kp n
            for c in range(3):
                dfn = -kp * n[c]
                dst = cv * e_t[c]
                dsm = cv * t_m[c]
                dft_t = a_tt * dst + a_tm * dsm + b_t * dfn
                dft_m = a_mt * dst + a_mm * dsm + b_m * dfn
                D[r, c] = dfn * n[r] + dft_t * e_t[r] + dft_m * t_m[r]
            # dz: d fn = -kA sin_a, d s_m = -cv cos_a
            dfn = -kp * sin_a
            dsm = -cv * cos_a
            dft_t = a_tm * dsm + b_t * dfn
            dft_m = a_mm * dsm + b_m * dfn
            dfdz[r] = dfn * n[r] + dft_t * e_t[r] + dft_m * t_m[r]
            # Omega: d s_t = -rho
            dst = -rho[i]
            dfds[r] = a_tt * dst * e_t[r] + a_mt * dst * t_m[r]
    return fn, s_t, s_m


@njit(cache=True, error_model="numpy")
def _rotor_load(fc, frame, rho):
    """Axial force [N] and torque about z [N m] the rotor takes from the contact points' forces fc (n_c, 3) on
    the stator (it takes -fc)."""
    axial = 0.0
    torque = 0.0
    for i in range(rho.size):
        et = frame[i, 1]
        axial -= fc[i, 2]
        torque -= rho[i] * (et[0] * fc[i, 0] + et[1] * fc[i, 1] + et[2] * fc[i, 2])
    return axial, torque


@njit(cache=True, error_model="numpy")
def _contact_buffers(nB, n_c):
    """Work arrays of :func:`_evaluate` for nB interface DOFs and n_c contact points: nodal forces fB, point
    forces fc, their derivatives (own displacement, dz, Omega), normal forces, slips, point displacements and
    velocities."""
    return (np.zeros(nB), np.zeros((n_c, 3)), np.zeros((n_c, 3, 3)), np.zeros((n_c, 3)), np.zeros((n_c, 3)),
            np.zeros(n_c), np.zeros((n_c, 2)), np.zeros((n_c, 3)), np.zeros((n_c, 3)))


@njit(cache=True, error_model="numpy")
def _evaluate(uB, vB, dz, dz_rate, spin, frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact, decay, tau_cap,
              eps, cv, fB, fc, Dall, dfdz_all, dfds_all, fn_all, s_all, uc_all, vc_all, want_jacobian):
    """Forces at all contact points (fc, their derivatives with respect to the point's own displacement in
    Dall, to dz and Omega in dfdz_all, dfds_all) and on the interface nodes (fB = P^T fc, 3 per node), and the
    rotor's axial force and torque. A contact point's displacement and velocity are interpolated from the
    interface nodes of its stencil: u_c = sum_s B[c, s] u_idx[c, s] (P, 3x3 blocks)."""
    n_c = rho.size
    n_s = idx.shape[1]
    f = np.zeros(3)
    uc = np.zeros(3)
    vc = np.zeros(3)
    empty = np.zeros((0, 0))
    fB[:] = 0.0
    for i in range(n_c):
        # the gap first (the normal component only): most points are separated and need nothing else
        n = frame[i, 0]
        gap = g0[i] + sin_a * dz
        for s in range(n_s):
            j = 3 * idx[i, s]
            for c in range(3):
                gap += (n[0] * B[i, s, 0, c] + n[1] * B[i, s, 1, c] + n[2] * B[i, s, 2, c]) * uB[j + c]
        if gap >= 0.0 and i > 0:      # point 0's displacement is always wanted (its path is an output)
            fn_all[i] = 0.0
            s_all[i, 0] = 0.0
            s_all[i, 1] = 0.0
            for r in range(3):
                fc[i, r] = 0.0
            continue
        for r in range(3):
            uc[r] = 0.0
            vc[r] = 0.0
        for s in range(n_s):
            j = 3 * idx[i, s]
            for r in range(3):
                for c in range(3):
                    uc[r] += B[i, s, r, c] * uB[j + c]
                    vc[r] += B[i, s, r, c] * vB[j + c]
        if want_jacobian:
            fn, s_t, s_m = _point_force(i, uc, vc, dz, dz_rate, spin, frame, g0, rho, area, sin_a, cos_a, k, mu_d,
                                        fact, decay, tau_cap, eps, cv, f, Dall[i], dfdz_all[i], dfds_all[i])
        else:
            fn, s_t, s_m = _point_force(i, uc, vc, dz, dz_rate, spin, frame, g0, rho, area, sin_a, cos_a, k, mu_d,
                                        fact, decay, tau_cap, eps, cv, f, empty, dfdz_all[i], dfds_all[i])
        fn_all[i] = fn
        s_all[i, 0] = s_t
        s_all[i, 1] = s_m
        for r in range(3):
            fc[i, r] = f[r]
            uc_all[i, r] = uc[r]
            vc_all[i, r] = vc[r]
        if fn > 0.0:
            for s in range(n_s):
                j = 3 * idx[i, s]
                for c in range(3):
                    fB[j + c] += B[i, s, 0, c] * f[0] + B[i, s, 1, c] * f[1] + B[i, s, 2, c] * f[2]
    return _rotor_load(fc, frame, rho)


@njit(cache=True, error_model="numpy")
def _residual(uB, dd, ds, w, G, xtB, vtB, cv, c_a, dz_t, dzr_t, spin_t, dt, gamma, frame, g0, rho, area, idx, B,
              sin_a, cos_a, k, mu_d, fact, decay, tau_cap, eps, rotor_mass, preload, inertia, load_torque, brake,
              spin_free, fB, fc, Dall, dfdz, dfds, fn_all, s_all, uc_all, vc_all, vB, Ru, want_jacobian):
    """Residuals of the condensed step at (uB, dz_t + dd, spin_t + ds): Ru (in place), Rz, Rs, axial force, torque.
    The rotor's unknowns are corrections to their predictors, so that m c_a dz and J Omega / (gamma dt), large
    against the forces, never enter the residual (round-off)."""
    spin = spin_t + ds
    nB = uB.size
    for r in range(nB):
        vB[r] = vtB[r] + cv * (uB[r] - xtB[r])
    dz = dz_t + dd
    dz_rate = dzr_t + cv * dd
    axial, torque = _evaluate(uB, vB, dz, dz_rate, spin, frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact,
                              decay, tau_cap, eps, cv, fB, fc, Dall, dfdz, dfds, fn_all, s_all, uc_all, vc_all,
                              want_jacobian)
    # G @ fB over the nodes that carry a force only (a few per crest)
    for r in range(nB):
        Ru[r] = uB[r] - w[r]
    for j in range(nB // 3):
        if fB[3 * j] != 0.0 or fB[3 * j + 1] != 0.0 or fB[3 * j + 2] != 0.0:
            for c in range(3):
                fj = fB[3 * j + c]
                for r in range(nB):
                    Ru[r] -= G[r, 3 * j + c] * fj
    Rz = rotor_mass * c_a * dd + preload - axial
    Rs = 0.0
    if spin_free:
        Rs = inertia * ds / (gamma * dt) - load_torque + brake * spin - torque
    return Rz, Rs, axial, torque


@njit(cache=True, error_model="numpy")
def _newton_system(Ru, Rz, Rs, G, Dall, dfdz, dfds, fn_all, frame, rho, idx, B, n_b, rotor_mass, c_a, inertia, gamma,
                   dt, brake, spin_free):
    """Newton matrix and residual on the interface nodes that carry a force (the stencil nodes of the contact
    points in contact; 3 unknowns per node) plus dz and Omega: the rows of the condensed interface equations
    u - w - G P^T f(P u) = 0 of those nodes and the rotor's two equations (a node without force has no force
    derivative, so its rows decouple; the caller recovers it). Returns (J, R, active node list, count, and the
    nodal force derivatives DF = d(P^T f)/du_A, dFz, dFs on the active nodes)."""
    n_c = fn_all.size
    n_s = idx.shape[1]
    position = np.full(n_b, -1, np.int64)
    active = np.zeros(n_b, np.int64)
    na = 0
    for i in range(n_c):
        if fn_all[i] > 0.0:
            for s in range(n_s):
                j = idx[i, s]
                if position[j] < 0:
                    position[j] = na
                    active[na] = j
                    na += 1
    m = 3 * na + 2
    J = np.zeros((m, m))
    R = np.zeros(m)
    DF = np.zeros((3 * na, 3 * na))
    dFz = np.zeros(3 * na)
    dFs = np.zeros(3 * na)
    E = np.zeros((n_s, 3, 3))
    for i in range(n_c):
        if fn_all[i] <= 0.0:
            continue
        et = frame[i, 1]
        for s2 in range(n_s):
            for r in range(3):
                for c in range(3):
                    E[s2, r, c] = Dall[i, r, 0] * B[i, s2, 0, c] + Dall[i, r, 1] * B[i, s2, 1, c] \
                        + Dall[i, r, 2] * B[i, s2, 2, c]
        for s1 in range(n_s):
            a1 = 3 * position[idx[i, s1]]
            for s2 in range(n_s):
                a2 = 3 * position[idx[i, s2]]
                for r in range(3):
                    for c in range(3):
                        DF[a1 + r, a2 + c] += B[i, s1, 0, r] * E[s2, 0, c] + B[i, s1, 1, r] * E[s2, 1, c] \
                            + B[i, s1, 2, r] * E[s2, 2, c]
            for r in range(3):
                dFz[a1 + r] += B[i, s1, 0, r] * dfdz[i, 0] + B[i, s1, 1, r] * dfdz[i, 1] + B[i, s1, 2, r] * dfdz[i, 2]
                dFs[a1 + r] += B[i, s1, 0, r] * dfds[i, 0] + B[i, s1, 1, r] * dfds[i, 1] + B[i, s1, 2, r] * dfds[i, 2]
        # rotor rows: axial = -sum f_z, torque = -sum rho e_t.f over the contact points
        for s2 in range(n_s):
            a2 = 3 * position[idx[i, s2]]
            for c in range(3):
                J[m - 2, a2 + c] += E[s2, 2, c]
                if spin_free:
                    J[m - 1, a2 + c] += rho[i] * (et[0] * E[s2, 0, c] + et[1] * E[s2, 1, c] + et[2] * E[s2, 2, c])
        J[m - 2, m - 2] += dfdz[i, 2]
        J[m - 2, m - 1] += dfds[i, 2]
        if spin_free:
            J[m - 1, m - 2] += rho[i] * (et[0] * dfdz[i, 0] + et[1] * dfdz[i, 1] + et[2] * dfdz[i, 2])
            J[m - 1, m - 1] += rho[i] * (et[0] * dfds[i, 0] + et[1] * dfds[i, 1] + et[2] * dfds[i, 2])
    # rows of the active nodes: Ru_A = u_A - w_A - G_A. P^T f
    GA = np.empty((3 * na, 3 * na))
    for ia in range(na):
        for r in range(3):
            gi = 3 * active[ia] + r
            R[3 * ia + r] = Ru[gi]
            for ja in range(na):
                for c in range(3):
                    GA[3 * ia + r, 3 * ja + c] = G[gi, 3 * active[ja] + c]
    if na > 0:
        J[:3 * na, :3 * na] = np.eye(3 * na) - GA @ DF
        J[:3 * na, m - 2] = -(GA @ dFz)
        J[:3 * na, m - 1] = -(GA @ dFs)
    R[m - 2] = Rz
    J[m - 2, m - 2] += rotor_mass * c_a
    if spin_free:
        R[m - 1] = Rs
        J[m - 1, m - 1] += inertia / (gamma * dt) + brake
    else:
        R[m - 1] = 0.0
        for c in range(m):
            J[m - 1, c] = 0.0
        J[m - 1, m - 1] = 1.0
    return J, R, active, na, DF, dFz, dFs


@njit(cache=True, error_model="numpy")
def _step(dt, level_inv, t0, q, v, a, rot, K, M, C, free, prescribed, n_b, amp, phase, omega, cosine, beta,
          gamma, frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact, decay, tau_cap, eps, rotor_mass, preload,
          inertia, load_torque, brake, spin_free, tol_u, out_q, out_v, out_a, out_rot, work):
    """One Newmark step of size dt from (q, v, a, rot); Kinv = the free block's K_eff^-1 for dt.
    rot = [dz, dz', dz'', angle, Omega, Omega']. Returns (converged, Newton iterations)."""
    Kinv = level_inv
    n = q.size
    nf = free.size
    t1 = t0 + dt
    c_a = 1.0 / (beta * dt * dt)
    cv = gamma / (beta * dt)
    # predictors x~ = x + dt v + dt^2 (1/2 - beta) a, v~ = v + dt (1 - gamma) a
    xt = q + dt * v + dt * dt * (0.5 - beta) * a
    vt = v + dt * (1.0 - gamma) * a
    x1 = np.empty(n)
    x1[:] = xt
    vp = np.empty(prescribed.size)
    _drive(t1, amp, phase, omega, cosine, vp)
    for j in range(prescribed.size):
        x1[prescribed[j]] = vp[j]
    # K_eff x1 = M x~ c_a + C (cv x~ - v~) + f_c ; f_c on the interface only
    rhs_all = M @ (c_a * xt) + C @ (cv * xt - vt)
    Keff_xP = np.zeros(n)
    for j in range(prescribed.size):
        p = prescribed[j]
        col = x1[p]
        for r in range(n):
            Keff_xP[r] += (K[r, p] + cv * C[r, p] + c_a * M[r, p]) * col
    r_free = np.empty(nf)
    for r in range(nf):
        r_free[r] = rhs_all[free[r]] - Keff_xP[free[r]]
    w = Kinv @ r_free
    nB = 3 * n_b                     # the interface coordinates are the first nB free coordinates
    G = Kinv[:nB, :nB]
    # rotor predictors
    dz_t = rot[0] + dt * rot[1] + dt * dt * (0.5 - beta) * rot[2]
    dzr_t = rot[1] + dt * (1.0 - gamma) * rot[2]
    spin0 = rot[4]
    # unknowns: uB, dz, spin; start from the predictor
    uB = w[:nB].copy()
    dd = 0.0                         # dz - dz_t: the unknown is the correction (no round-off of m c_a dz)
    dz = dz_t
    # Newmark on the angle: Omega_1 = Omega_t + gamma dt Omega'_1, Omega_t = Omega_0 + (1 - gamma) dt Omega'_0
    spin_t = spin0 + (1.0 - gamma) * dt * rot[5] if spin_free else spin0
    ds = gamma * dt * rot[5] if spin_free else 0.0
    spin = spin_t + ds
    fB, fc, Dall, dfdz, dfds, fn_all, s_all, uc_all, vc_all = _contact_buffers(nB, rho.size)
    vB = np.zeros(nB)
    xtB = np.empty(nB)
    vtB = np.empty(nB)
    for r in range(nB):
        xtB[r] = xt[free[r]]
        vtB[r] = vt[free[r]]
    # force scale of the step: the preload, or with none (a rotor let go) the contact forces of the predictor
    force_scale = max(preload, 1e-3 * rotor_mass * 9.81)
    torque_scale = max(abs(load_torque), mu_d * fact * force_scale * np.max(rho), 1e-30)
    converged = False
    its = 0
    Ru = np.zeros(nB)
    Ru_trial = np.zeros(nB)
    u_trial = np.zeros(nB)
    ftol = 1e-10 * force_scale
    ttol = 1e-10 * torque_scale
    Rz, Rs, axial, torque = _residual(uB, dd, ds, w, G, xtB, vtB, cv, c_a, dz_t, dzr_t, spin_t, dt, gamma,
                                      frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact, decay, tau_cap, eps,
                                      rotor_mass, preload, inertia, load_torque, brake, spin_free, fB, fc, Dall,
                                      dfdz, dfds, fn_all, s_all, uc_all, vc_all, vB, Ru, True)
    lam_last = 1.0
    for its in range(1, MAX_NEWTON + 1):
        res = max(np.max(np.abs(Ru)) / tol_u, abs(Rz) / ftol, abs(Rs) / ttol)
        if DEBUG:
            print("newton", dt, its, lam_last, res, np.max(np.abs(Ru)), Rz, Rs, dz_t + dd, spin, np.sum(fn_all > 0.0))
        if res <= 1.0:
            converged = True
            break
        J, R, active, na, DF, dFz, dFs = _newton_system(Ru, Rz, Rs, G, Dall, dfdz, dfds, fn_all, frame, rho, idx, B,
                                                        n_b, rotor_mass, c_a, inertia, gamma, dt, brake, spin_free)
        m = 3 * na + 2
        dy = np.linalg.solve(J, -R)
        # inactive nodes: du_I = -Ru_I + G_IA (D_A du_A + dfdz dz + dfds ds)
        df = np.zeros(nB)
        if na > 0:
            dF_A = DF @ dy[:m - 2] + dFz * dy[m - 2] + dFs * dy[m - 1]
            for ja in range(na):
                for d in range(3):
                    df[3 * active[ja] + d] = dF_A[3 * ja + d]
        du = -Ru + G @ df
        for ia in range(na):
            i = active[ia]
            for c in range(3):
                du[3 * i + c] = dy[3 * ia + c]
        # Damped Newton with the natural monotonicity test (Deuflhard): a trial point is accepted when the
        # simplified Newton correction there, J^-1 R(trial) with this iteration's J, is shorter than the
        # Newton correction (in the unknowns' own scales). Affine invariant, so the mixed units of the
        # residuals (m, N, N m) do not steer the damping, as a residual-norm merit would.
        scale = np.empty(m)
        scale[:m - 2] = UNKNOWN_SCALE_M
        scale[m - 2] = UNKNOWN_SCALE_M
        scale[m - 1] = SPIN_SCALE_RAD_PER_S
        size0 = np.sqrt(np.sum((dy / scale) ** 2))
        lam = 1.0
        R_trial = np.zeros(m)
        for _ in range(14):
            u_trial[:] = uB + lam * du
            dd_trial = dd + lam * dy[m - 2]
            ds_trial = ds + lam * dy[m - 1] if spin_free else ds
            Rz_t, Rs_t, axial, torque = _residual(u_trial, dd_trial, ds_trial, w, G, xtB, vtB, cv, c_a, dz_t,
                                                  dzr_t, spin_t, dt, gamma, frame, g0, rho, area, idx, B,
                                                  sin_a, cos_a, k, mu_d, fact, decay, tau_cap, eps, rotor_mass,
                                                  preload, inertia, load_torque, brake, spin_free, fB, fc, Dall,
                                                  dfdz, dfds, fn_all, s_all, uc_all, vc_all, vB, Ru_trial, True)
            for ia in range(na):
                i = active[ia]
                for c in range(3):
                    R_trial[3 * ia + c] = Ru_trial[3 * i + c]
            R_trial[m - 2] = Rz_t
            R_trial[m - 1] = Rs_t if spin_free else 0.0
            simplified = np.linalg.solve(J, -R_trial)
            if np.sqrt(np.sum((simplified / scale) ** 2)) <= (1.0 - 0.5 * lam) * size0 + 1e-300:
                break
            lam *= 0.5
        lam_last = lam
        stalled = lam < 1e-3
        uB[:] = u_trial
        dd = dd_trial
        ds = ds_trial
        spin = spin_t + ds
        Ru[:] = Ru_trial
        Rz = Rz_t
        Rs = Rs_t
        if stalled and res < ROUND_OFF_FACTOR:
            # no descent left within a few of the tolerances: the residual is at its round-off floor
            converged = True
            break
    dz = dz_t + dd
    if not converged:
        return False, its
    # recover the free coordinates, then Newmark updates
    for r in range(nB):
        vB[r] = vtB[r] + cv * (uB[r] - xtB[r])
    x_free = w + Kinv[:, :nB] @ fB
    for r in range(nf):
        x1[free[r]] = x_free[r]
    for r in range(n):
        out_q[r] = x1[r]
        out_a[r] = c_a * (x1[r] - xt[r])
        out_v[r] = vt[r] + gamma * dt * out_a[r]
    out_rot[0] = dz
    out_rot[2] = c_a * dd
    out_rot[1] = dzr_t + gamma * dt * out_rot[2]
    if spin_free:
        out_rot[5] = ds / (gamma * dt)
    else:
        out_rot[5] = 0.0
    out_rot[4] = spin
    out_rot[3] = rot[3] + 0.5 * dt * (spin0 + spin)
    # the converged forces and slips for the caller
    work[0] = axial
    work[1] = torque
    return True, its


@njit(cache=True, error_model="numpy")
def run_period(t0, n_steps, dt, level_invs, max_level, q, v, a, rot, energies, istate, K, M, C, free, prescribed,
               n_b, amp, phase, omega, cosine, beta, gamma, frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact,
               decay, tau_cap, eps, rotor_mass, preload, inertia, load_torque, brake, spin_free, tol_u, charge_rows,
               columns, point_state, point_fn, trajectory):
    """Advance n_steps steps of dt from t0 (cutting a failed step into halves, up to max_level).

    Per step: ``columns`` row (time, rotor state, contact sums, cumulative energies), ``point_state``
    per contact point (separated / stick / forward / backward slip, forward = the stator slipping ahead of
    the rotor in the +theta direction), ``point_fn`` their normal forces [N], ``trajectory`` the stator's
    displacement at contact point 0 (n, theta, m components). ``energies`` = [electrical input, damping,
    friction, output] [J], carried between calls. Returns the time reached (t0 + n_steps dt unless a
    step failed at the smallest size: then istate[I_FAILED] = 1)."""
    n = q.size
    nB = 3 * n_b
    qn = np.empty(n)
    vn = np.empty(n)
    an = np.empty(n)
    rotn = np.empty(6)
    work = np.zeros(2)
    n_c = rho.size
    fB, fc, Dd, dfdz, dfds, fn_all, s_all, uc_all, vc_all = _contact_buffers(nB, n_c)
    n_el = prescribed.size
    volts0 = np.empty(n_el)
    volts1 = np.empty(n_el)
    t = t0
    # friction power at the start of the step (trapezoidal dissipation)
    axial_now, torque_now = _evaluate(q[:nB], v[:nB], rot[0], rot[1], rot[4], frame, g0, rho, area, idx, B, sin_a,
                                      cos_a, k, mu_d, fact, decay, tau_cap, eps, 0.0, fB, fc, Dd, dfdz, dfds, fn_all,
                                      s_all, uc_all, vc_all, False)
    p_fric0 = _friction_power(fc, s_all, frame)
    for step in range(n_steps):
        # Newmark step, retried as 2^level sub-steps on failure
        level = 0
        ok = False
        its_total = 0
        fB_step0 = fB.copy()
        axial_step0, torque_step0 = axial_now, torque_now
        while not ok:
            fB[:] = fB_step0
            sub = 2 ** level
            h = dt / sub
            qn[:] = q
            vn[:] = v
            an[:] = a
            rotn[:] = rot
            ok = True
            e_in = 0.0
            e_d = 0.0
            e_f = 0.0
            e_o = 0.0
            e_r = 0.0
            e_c = 0.0
            e_rot = 0.0
            axial0 = axial_step0
            torque0 = torque_step0
            tt = t
            pf0 = p_fric0
            Kinv = np.ascontiguousarray(level_invs[level])     # once per attempt, not per sub-step
            for _sub in range(sub):
                qa = qn.copy()
                va = vn.copy()
                aa = an.copy()
                ra = rotn.copy()
                conv, its = _step(h, Kinv, tt, qa, va, aa, ra, K, M, C, free, prescribed, n_b, amp, phase, omega,
                                  cosine, beta, gamma, frame, g0, rho, area, idx, B, sin_a, cos_a, k, mu_d, fact, decay,
                                  tau_cap, eps, rotor_mass, preload, inertia, load_torque, brake, spin_free, tol_u,
                                  qn, vn, an, rotn, work)
                its_total += its
                if not conv:
                    ok = False
                    break
                # energies of the sub-step (trapezoidal: exact for the linear part under beta 1/4, gamma 1/2)
                _drive(tt, amp, phase, omega, cosine, volts0)
                _drive(tt + h, amp, phase, omega, cosine, volts1)
                for e in range(n_el):
                    dq = charge_rows[e] @ qn - charge_rows[e] @ qa
                    e_in += 0.5 * (volts0[e] + volts1[e]) * dq
                    pe = prescribed[e]
                    r0 = M[pe] @ aa + C[pe] @ va + K[pe] @ qa
                    r1 = M[pe] @ an + C[pe] @ vn + K[pe] @ qn
                    e_r += 0.5 * (r0 + r1) * (volts1[e] - volts0[e])
                fB_old = fB.copy()
                vm = 0.5 * (va + vn)
                e_d += h * (vm @ (C @ vm))
                axial1, torque1 = _evaluate(qn[:nB], vn[:nB], rotn[0], rotn[1], rotn[4], frame, g0, rho, area, idx,
                                            B, sin_a, cos_a, k, mu_d, fact, decay, tau_cap, eps, 0.0, fB, fc, Dd,
                                            dfdz, dfds, fn_all, s_all, uc_all, vc_all, False)
                pf1 = _friction_power(fc, s_all, frame)
                for r in range(nB):
                    e_c -= 0.5 * (fB_old[r] + fB[r]) * (qn[r] - qa[r])
                e_rot += 0.5 * (axial0 + axial1) * (rotn[0] - ra[0]) + 0.5 * (torque0 + torque1) * (rotn[3] - ra[3])
                if not spin_free:
                    # a prescribed or held spin: the constraint takes the contact torque's work as the output
                    e_o += 0.5 * (torque0 + torque1) * (rotn[3] - ra[3])
                axial0 = axial1
                torque0 = torque1
                e_f += 0.5 * h * (pf0 + pf1)
                pf0 = pf1
                if spin_free:
                    # a free spin: the output is the work against the load torque and the brake
                    t_ap0 = load_torque - brake * ra[4]
                    t_ap1 = load_torque - brake * rotn[4]
                    e_o -= 0.5 * h * (t_ap0 * ra[4] + t_ap1 * rotn[4])
                tt += h
            if not ok:
                level += 1
                if level > max_level:
                    istate[I_FAILED] = 1
                    return t
        if level > 0:
            istate[I_CUTBACKS] += 1
        istate[I_STEPS] += 1
        istate[I_NEWTON] += its_total
        q[:] = qn
        v[:] = vn
        a[:] = an
        rot[:] = rotn
        t += dt
        p_fric0 = pf0
        axial_now, torque_now = axial0, torque0
        energies[0] += e_in
        energies[1] += e_d
        energies[2] += e_f
        energies[3] += e_o
        energies[4] += e_r
        energies[5] += e_c
        energies[6] += e_rot
        # outputs at the end of the step (forces from the last evaluation at (q, v, rot))
        normal = 0.0
        drive_num = 0.0
        active = 0
        for i in range(n_c):
            normal += fn_all[i]
            if fn_all[i] > 0.0:
                active += 1
                et = frame[i, 1]
                drive_num += fn_all[i] * (et[0] * vc_all[i, 0] + et[1] * vc_all[i, 1] + et[2] * vc_all[i, 2])
            speed = np.sqrt(s_all[i, 0] ** 2 + s_all[i, 1] ** 2)
            if fn_all[i] <= 0.0:
                point_state[step, i] = SEPARATED
            elif speed <= eps:
                point_state[step, i] = STICK
            elif s_all[i, 0] > 0.0:
                point_state[step, i] = FORWARD_SLIP
            else:
                point_state[step, i] = BACKWARD_SLIP
            point_fn[step, i] = fn_all[i]
        axial, torque = axial_now, torque_now
        for r in range(3):
            trajectory[step, r] = frame[0, r, 0] * uc_all[0, 0] + frame[0, r, 1] * uc_all[0, 1] \
                + frame[0, r, 2] * uc_all[0, 2]
        stored = 0.5 * (v @ (M @ v)) + 0.5 * (q @ (K @ q)) + 0.5 * rotor_mass * rot[1] ** 2 \
            + 0.5 * inertia * rot[4] ** 2 + preload * rot[0]
        penalty = 0.0
        for i in range(n_c):
            if fn_all[i] > 0.0:
                gap = g0[i] + sin_a * rot[0]
                for c in range(3):
                    gap += frame[i, 0, c] * uc_all[i, c]
                penalty += _penalty(-gap, k * area[i])[2]
        stored += penalty
        columns[step, C_TIME] = t
        columns[step, C_DZ] = rot[0]
        columns[step, C_DZ_RATE] = rot[1]
        columns[step, C_SPIN] = rot[4]
        columns[step, C_ANGLE] = rot[3]
        columns[step, C_NORMAL] = normal
        columns[step, C_AXIAL] = axial
        columns[step, C_TORQUE] = torque
        columns[step, C_DRIVE_SPEED] = drive_num / normal if normal > 0.0 else 0.0
        columns[step, C_ACTIVE] = active
        columns[step, C_E_EL] = energies[0]
        columns[step, C_E_DAMP] = energies[1]
        columns[step, C_E_FRIC] = energies[2]
        columns[step, C_E_OUT] = energies[3]
        columns[step, C_E_STORED] = stored
        columns[step, C_NEWTON] = its_total
        columns[step, C_E_REACTION] = energies[4]
        columns[step, C_E_CONTACT] = energies[5]
        columns[step, C_E_ROTOR] = energies[6]
        columns[step, C_E_PENALTY] = penalty
    return t


@njit(cache=True, error_model="numpy")
def _friction_power(fc, s_all, frame):
    """Power dissipated by friction [W]: -f_t . s summed over the contact points (f_t the tangential force on
    the stator, s its slip over the rotor)."""
    p = 0.0
    for i in range(s_all.shape[0]):
        et = frame[i, 1]
        tm = frame[i, 2]
        ft_t = et[0] * fc[i, 0] + et[1] * fc[i, 1] + et[2] * fc[i, 2]
        ft_m = tm[0] * fc[i, 0] + tm[1] * fc[i, 1] + tm[2] * fc[i, 2]
        p -= ft_t * s_all[i, 0] + ft_m * s_all[i, 1]
    return p
