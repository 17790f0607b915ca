"""Generalized-alpha time stepping of a reduced (Craig-Bampton) model without contact.

The same scheme and the same discrete equations as the FE tier (:mod:`forms.newmark`), on the
reduced coordinates q = [u_B; V_E; eta]. Driven electrode potentials are prescribed coordinates:
their values are set at t_{n+1} and their velocity and acceleration follow through the Newmark
updates, exactly as the FE tier treats its Dirichlet DOFs. That matters here, unlike in the FE tier
where potentials are massless: an electrode mode carries the mass of the deformation it causes,
and the generalized-alpha acceleration variable is not the acceleration at t_{n+1} (it lags by
(alpha_f - alpha_m) dt); feeding in the exact second derivative instead shifts the electrode
mode's inertial forcing in time, a first-order error (4 % in the 1 ms tip history of
tests/test_reduced_transient.py, against 4e-5 with consistent updates). The free coordinates are
solved with one dense LU per step size. This is the linear part every reduced transient shares;
contacts act on the interface coordinates on top of it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from app.reduced.craig_bampton import ReducedBasis
from forms.newmark import TimeScheme, acceleration, acceleration_per_displacement, velocity, velocity_per_displacement


@dataclass
class ReducedState:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray


class ReducedLinearStepper:
    """``prescribed(t)`` returns (values, first, second time derivatives) of the driven electrode
    coordinates at t, in the order of ``prescribed_index`` (the derivatives are used at the start
    only); ``load(t)`` the generalized load vector (size of q) at t."""

    def __init__(self, basis: ReducedBasis, scheme: TimeScheme, prescribed_index: np.ndarray,
                 prescribed: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]],
                 load: Callable[[float], np.ndarray] | None = None):
        self.K, self.M = basis.K, basis.M
        self.C = basis.C if basis.C is not None else np.zeros_like(basis.K)
        self.scheme = scheme
        self.P = np.asarray(prescribed_index, dtype=int)
        self.F = np.setdiff1d(np.arange(basis.size), self.P)
        self.prescribed = prescribed
        self.load = load
        self._factors: dict[float, tuple] = {}

    def _factor(self, dt: float):
        key = float(f"{dt:.12e}")
        if key not in self._factors:
            s = self.scheme
            A = ((1 - s.alpha_m) * acceleration_per_displacement(dt, s) * self.M
                 + (1 - s.alpha_f) * velocity_per_displacement(dt, s) * self.C + (1 - s.alpha_f) * self.K)
            self._factors[key] = scipy.linalg.lu_factor(A[np.ix_(self.F, self.F)])
        return self._factors[key]

    def initial_state(self, t0: float, q0: np.ndarray | None = None, v0: np.ndarray | None = None) -> ReducedState:
        """State at t0 with the acceleration from the equations of motion. Default: the body at
        rest. A driven electrode coordinate moving at t0 (U = V sin wt starts with dU/dt = V w)
        would move its electrode mode's material: the free coordinates then start with the
        velocity that cancels it, v_F = -M_FF^-1 M_FP v_P (the M-orthogonal projection of a zero
        velocity field onto the basis), as the FE tier starts with every displacement DOF at rest."""
        n = self.K.shape[0]
        q = np.zeros(n) if q0 is None else np.array(q0, dtype=float)
        v = np.zeros(n) if v0 is None else np.array(v0, dtype=float)
        a = np.zeros(n)
        q[self.P], v[self.P], a[self.P] = self.prescribed(t0)
        F, P = self.F, self.P
        if q0 is None:
            q[F] = -np.linalg.solve(self.M[np.ix_(F, F)], self.M[np.ix_(F, P)] @ q[P])
        if v0 is None:
            v[F] = -np.linalg.solve(self.M[np.ix_(F, F)], self.M[np.ix_(F, P)] @ v[P])
        rhs = (self.load(t0) if self.load is not None else np.zeros(n)) - self.K @ q - self.C @ v - self.M @ a
        a[F] = np.linalg.solve(self.M[np.ix_(F, F)], rhs[F])
        return ReducedState(t0, q, v, a)

    def step(self, state: ReducedState, dt: float) -> ReducedState:
        s = self.scheme
        t1 = state.t + dt
        q0, v0, a0 = state.q, state.v, state.a
        q1 = q0 + dt * v0 + 0.5 * dt * dt * a0          # predictor; the correction is exact (linear)
        P = self.P
        exact = self.prescribed(t1)
        q1[P] = exact[0]
        a1 = acceleration(q1, q0, v0, a0, dt, s)
        v1 = velocity(a1, v0, a0, dt, s)
        t_mid = (1 - s.alpha_f) * t1 + s.alpha_f * state.t
        r = (self.M @ ((1 - s.alpha_m) * a1 + s.alpha_m * a0) + self.C @ ((1 - s.alpha_f) * v1 + s.alpha_f * v0)
             + self.K @ ((1 - s.alpha_f) * q1 + s.alpha_f * q0))
        if self.load is not None:
            r = r - self.load(t_mid)
        q1[self.F] -= scipy.linalg.lu_solve(self._factor(dt), r[self.F])
        a1 = acceleration(q1, q0, v0, a0, dt, s)
        v1 = velocity(a1, v0, a0, dt, s)
        return ReducedState(t1, q1, v1, a1)
