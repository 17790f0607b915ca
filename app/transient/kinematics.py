"""The generalized-alpha end-of-step and mid-point kinematics of many DOFs in one pass (numba).

:func:`forms.newmark.acceleration`, :func:`~forms.newmark.velocity` and :func:`~forms.newmark.midpoint` applied
to arrays make ~15 passes with temporaries; the condensed step (app/transient/coupled.py) applies them to every
FE DOF once a step, to its evaluation DOFs and to the rigid coordinates at every Newton iterate, where numpy's
call overhead on a few entries dominates. These kernels evaluate the same expressions entry by entry, in the same
order and with the same scalar factors, so the values are those of forms/newmark.py bit for bit (numba does not
contract to fused multiply-adds unless asked: no ``fastmath``); tests/test_transient_newmark.py checks it.
"""

from __future__ import annotations

from numba import njit

from forms.newmark import TimeScheme


def scheme_factors(dt: float, scheme: TimeScheme) -> tuple[float, float, float, float, float, float]:
    """The scalars of forms/newmark.py's expressions at step ``dt``: (dt, beta dt^2, 1 / (2 beta) - 1,
    1 - gamma, gamma, alpha_f) (each formed as there)."""
    return (float(dt), scheme.beta * dt * dt, 1 / (2 * scheme.beta) - 1, 1 - scheme.gamma, scheme.gamma,
            scheme.alpha_f)


@njit(cache=True)
def _one(u_new, u_old, v_old, a_old, dt, beta_dt2, a_factor, one_minus_gamma, gamma, alpha_f):
    a_new = (u_new - u_old - dt * v_old) / beta_dt2 - a_factor * a_old
    v_new = v_old + dt * (one_minus_gamma * a_old + gamma * a_new)
    return a_new, v_new, (1 - alpha_f) * u_new + alpha_f * u_old, (1 - alpha_f) * v_new + alpha_f * v_old


@njit(cache=True)
def step_kinematics(u_new, u_old, v_old, a_old, factors, a_new, v_new, u_mid, v_mid):
    """a_{n+1}, v_{n+1} and the mid-point u, v of every entry, into the four output arrays (one simple loop
    per output, which the compiler vectorises: 2.5x faster than one loop writing all four)."""
    step_rates(u_new, u_old, v_old, a_old, factors, a_new, v_new)
    alpha_f = factors[5]
    n = u_new.size
    for i in range(n):
        u_mid[i] = (1 - alpha_f) * u_new[i] + alpha_f * u_old[i]
    for i in range(n):
        v_mid[i] = (1 - alpha_f) * v_new[i] + alpha_f * v_old[i]


@njit(cache=True)
def step_rates(u_new, u_old, v_old, a_old, factors, a_new, v_new):
    """a_{n+1} and v_{n+1} of every entry (:func:`step_kinematics` without the mid-points)."""
    dt, beta_dt2, a_factor, one_minus_gamma, gamma, _ = factors
    n = u_new.size
    for i in range(n):
        a_new[i] = (u_new[i] - u_old[i] - dt * v_old[i]) / beta_dt2 - a_factor * a_old[i]
    for i in range(n):
        v_new[i] = v_old[i] + dt * (one_minus_gamma * a_old[i] + gamma * a_new[i])


@njit(cache=True)
def step_kinematics_at(at, u_new, u_old, v_old, a_old, factors, a_new, v_new, u_mid, v_mid):
    """:func:`step_kinematics` at the entries ``at`` only (the other entries of the outputs untouched)."""
    dt, beta_dt2, a_factor, one_minus_gamma, gamma, alpha_f = factors
    for k in range(at.size):
        i = at[k]
        a_new[i], v_new[i], u_mid[i], v_mid[i] = _one(u_new[i], u_old[i], v_old[i], a_old[i], dt, beta_dt2,
                                                      a_factor, one_minus_gamma, gamma, alpha_f)


@njit(cache=True)
def increment_kinematics(du, u_new, u_old, v_old, a_old, factors, a_new, v_new, u_mid, v_mid):
    """:func:`step_kinematics` with the acceleration formed from the increment ``du`` = u_new - u_old
    (``acceleration(du, 0.0, ...)``: the rigid coordinates, whose increments are the unknowns)."""
    dt, beta_dt2, a_factor, one_minus_gamma, gamma, alpha_f = factors
    for i in range(du.size):
        a_new[i], v_new[i], _, v_mid[i] = _one(du[i], 0.0, v_old[i], a_old[i], dt, beta_dt2, a_factor,
                                               one_minus_gamma, gamma, alpha_f)
        u_mid[i] = (1 - alpha_f) * u_new[i] + alpha_f * u_old[i]


@njit(cache=True)
def taylor_predictor(u_old, v_old, a_old, dt, out, bc, out_bc):
    """out = u_n + dt v_n + dt^2/2 a_n, formed as (v_n dt + u_n) + (dt^2/2) a_n; ``out_bc`` its values at ``bc``."""
    half_dt2 = 0.5 * dt * dt
    for i in range(out.size):
        out[i] = v_old[i] * dt + u_old[i] + half_dt2 * a_old[i]
    for k in range(bc.size):
        out_bc[k] = out[bc[k]]


@njit(cache=True)
def predictor_arguments(u_pred, u_old, v_old, a_old, dt, bc, taylor_bc, mass_factor, damping_factor,
                        one_minus_alpha_f, mass_arg, stiffness_arg, damping_arg):
    """The arguments of the predictor residual's M, K and C mat-vecs (app/transient/coupled.py): with the
    Dirichlet change delta = u_pred - ``taylor_bc`` on the constrained DOFs ``bc``, a_n (+ ``mass_factor`` delta),
    (1 - alpha_f) u_pred + alpha_f u_n formed as (u_pred - u_n) (1 - alpha_f) + u_n, and
    (a_n dt (+ ``damping_factor`` delta)) (1 - alpha_f) + v_n."""
    n = u_pred.size
    for i in range(n):
        mass_arg[i] = a_old[i]
    for i in range(n):
        stiffness_arg[i] = (u_pred[i] - u_old[i]) * one_minus_alpha_f + u_old[i]
    for i in range(n):
        damping_arg[i] = a_old[i] * dt
    for k in range(bc.size):
        delta = u_pred[bc[k]] - taylor_bc[k]
        mass_arg[bc[k]] += mass_factor * delta
        damping_arg[bc[k]] += damping_factor * delta
    for i in range(n):
        damping_arg[i] = damping_arg[i] * one_minus_alpha_f + v_old[i]


@njit(cache=True)
def rigid_step_start(z_old, v_old, a_old, mass, load, factors, alpha_m, z_pred, inertia_sq, load_sq):
    """The rigid bodies' start of a step (app/transient/coupled.py), entry by entry as there: the predictor
    z_n + dt v_n + dt^2/2 a_n, the squared inertia m ((1 - alpha_m) a_hat + alpha_m a_n) of the round-off bound
    (a_hat = acceleration(0, 0, v_n, a_n)) and the squared load and inertia |F|^2 + |m a_n|^2 of the force scale."""
    dt, beta_dt2, a_factor, _, _, _ = factors
    half_dt2 = 0.5 * dt * dt
    for i in range(z_old.size):
        a_hat = (0.0 - 0.0 - dt * v_old[i]) / beta_dt2 - a_factor * a_old[i]
        inertia = mass[i] * ((1 - alpha_m) * a_hat + alpha_m * a_old[i])
        inertia_sq[i] = inertia * inertia
        momentum_rate = mass[i] * a_old[i]
        load_sq[i] = load[i] * load[i] + momentum_rate * momentum_rate
        z_pred[i] = z_old[i] + dt * v_old[i] + half_dt2 * a_old[i]
