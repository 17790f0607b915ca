"""Newmark and generalized-alpha time-integration kinematics.

Every update is written with ``+ - * /`` only, so the same function maps UFL fields and
``fem.Constant`` time steps to UFL expressions, or numpy arrays / PETSc-backed arrays to arrays.

Scheme (Chung & Hulbert 1993; HHT and plain Newmark are special cases): with unknown u_{n+1},

    a_{n+1} = (u_{n+1} - u_n - dt v_n) / (beta dt^2) - (1 / (2 beta) - 1) a_n
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

and the equation of motion is imposed at the generalised mid-points

    M a_{n+1-alpha_m} + C v_{n+1-alpha_f} + K u_{n+1-alpha_f} = F(t_{n+1-alpha_f}),
    x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n.

alpha_m = alpha_f = 0 is Newmark; beta = 1/4, gamma = 1/2 is the average-acceleration
(trapezoidal) rule: unconditionally stable, second order and without numerical damping.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TimeScheme:
    """Parameters of the generalized-alpha family (plain Newmark when both alphas are 0)."""

    beta: float = 0.25
    gamma: float = 0.5
    alpha_m: float = 0.0
    alpha_f: float = 0.0

    def __post_init__(self):
        if not self.beta > 0:
            raise ValueError(f"Newmark beta must be > 0, got {self.beta}")
        if not self.gamma >= 0:
            raise ValueError(f"Newmark gamma must be >= 0, got {self.gamma}")
        if not (0.0 <= self.alpha_f < 1.0 and -1.0 <= self.alpha_m < 1.0):
            raise ValueError(f"alpha_f must be in [0, 1) and alpha_m in [-1, 1), got "
                             f"{self.alpha_f}, {self.alpha_m}")

    @classmethod
    def newmark(cls, beta: float = 0.25, gamma: float = 0.5) -> TimeScheme:
        return cls(beta=beta, gamma=gamma)

    @classmethod
    def generalized_alpha(cls, rho_inf: float) -> TimeScheme:
        """Chung-Hulbert parameters: second order, spectral radius ``rho_inf`` as omega dt -> inf
        (1 = no damping, 0 = annihilates the highest frequencies in one step)."""
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf must be in [0, 1], got {rho_inf}")
        alpha_m = (2 * rho_inf - 1) / (rho_inf + 1)
        alpha_f = rho_inf / (rho_inf + 1)
        gamma = 0.5 - alpha_m + alpha_f
        beta = 0.25 * (1 - alpha_m + alpha_f) ** 2
        return cls(beta=beta, gamma=gamma, alpha_m=alpha_m, alpha_f=alpha_f)

    @classmethod
    def hht(cls, alpha: float) -> TimeScheme:
        """Hilber-Hughes-Taylor with the usual alpha in [-1/3, 0] (0 = trapezoidal rule)."""
        if not -1.0 / 3.0 <= alpha <= 0.0:
            raise ValueError(f"HHT alpha must be in [-1/3, 0], got {alpha}")
        return cls(beta=0.25 * (1 - alpha) ** 2, gamma=0.5 - alpha, alpha_m=0.0, alpha_f=-alpha)

    @property
    def is_second_order(self) -> bool:
        return math.isclose(self.gamma, 0.5 - self.alpha_m + self.alpha_f, abs_tol=1e-12)


def acceleration(u_new, u_old, v_old, a_old, dt, scheme: TimeScheme):
    """a_{n+1} from the new displacement and the old state."""
    return (u_new - u_old - dt * v_old) / (scheme.beta * dt * dt) - (1 / (2 * scheme.beta) - 1) * a_old


def velocity(a_new, v_old, a_old, dt, scheme: TimeScheme):
    """v_{n+1} from the new acceleration and the old state."""
    return v_old + dt * ((1 - scheme.gamma) * a_old + scheme.gamma * a_new)


def velocity_from_displacement(u_new, u_old, v_old, a_old, dt, scheme: TimeScheme):
    return velocity(acceleration(u_new, u_old, v_old, a_old, dt, scheme), v_old, a_old, dt, scheme)


def midpoint(x_new, x_old, alpha: float):
    """Generalised mid-point (1 - alpha) x_{n+1} + alpha x_n."""
    return (1 - alpha) * x_new + alpha * x_old


def acceleration_per_displacement(dt, scheme: TimeScheme):
    """d a_{n+1} / d u_{n+1} = 1 / (beta dt^2)."""
    return 1 / (scheme.beta * dt * dt)


def velocity_per_displacement(dt, scheme: TimeScheme):
    """d v_{n+1} / d u_{n+1} = gamma / (beta dt)."""
    return scheme.gamma / (scheme.beta * dt)


def effective_weights(dt, scheme: TimeScheme) -> tuple:
    """(w_M, w_C, w_K) with K_eff = w_M M + w_C C + w_K K the Jacobian of the mid-point equation of
    motion with respect to u_{n+1}."""
    return (
        (1 - scheme.alpha_m) * acceleration_per_displacement(dt, scheme),
        (1 - scheme.alpha_f) * velocity_per_displacement(dt, scheme),
        1 - scheme.alpha_f,
    )


def amplification_matrix(omega_dt: float, scheme: TimeScheme, damping_ratio: float = 0.0) -> np.ndarray:
    """One-step map of (omega u, v, a / omega) for the SDOF oscillator u'' + 2 zeta omega u' + omega^2 u = 0
    at omega = 1 (so ``omega_dt`` is the step size). Its spectral radius is the scheme's numerical
    damping per step; used to check rho_inf and that low frequencies are not damped."""
    dt = omega_dt
    zeta = damping_ratio
    cols = []
    for state in np.eye(3):
        u0, v0, a0 = state[0], state[1], state[2]
        w_m, w_c, w_k = effective_weights(dt, scheme)
        # Solve the mid-point equation (linear in u1) for u1.
        a_const = acceleration(0.0, u0, v0, a0, dt, scheme)
        v_const = velocity(a_const, v0, a0, dt, scheme)
        lhs = w_m + 2 * zeta * w_c + w_k
        rhs = -((1 - scheme.alpha_m) * a_const + scheme.alpha_m * a0
                + 2 * zeta * ((1 - scheme.alpha_f) * v_const + scheme.alpha_f * v0)
                + scheme.alpha_f * u0)
        u1 = rhs / lhs
        a1 = acceleration(u1, u0, v0, a0, dt, scheme)
        v1 = velocity(a1, v0, a0, dt, scheme)
        cols.append([u1, v1, a1])
    return np.array(cols).T


def spectral_radius(omega_dt: float, scheme: TimeScheme) -> float:
    return float(max(abs(np.linalg.eigvals(amplification_matrix(omega_dt, scheme)))))


def harmonic_rate_gains(omega: float, dt: float, beta: float, gamma: float) -> tuple[complex, complex]:
    """(g_v, g_a): a prescribed coordinate whose values follow a steady harmonic, q_n = Re(Q z^n) with
    z = exp(i omega dt), and whose rate and acceleration are advanced by the Newmark updates above from those
    values, settles on the rate and acceleration phasors g_v Q and g_a Q (the continuous ones are i omega and
    -omega^2; for the trapezoidal rule |g_v| = (2 / dt) tan(omega dt / 2)). A start on other phasors leaves
    an undamped step-to-step alternation of the difference."""
    z = np.exp(1j * omega * dt)
    g_a = (z - 1) / (dt * dt * (((1 - gamma) + gamma * z) / (z - 1) + 0.5 - beta + beta * z))
    g_v = dt * ((1 - gamma) + gamma * z) * g_a / (z - 1)
    return g_v, g_a
