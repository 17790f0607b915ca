"""The coupled step as a Newton iteration on all n + m unknowns (FE correction du and rigid
increments dz), the reference for :class:`app.transient.coupled.CoupledSystem`.

Same residual, tangents and tolerances; the Newton matrix

    [ A + E Kss E^T    E B ] [du]   [r_u]
    [ L E^T            Kzz ] [dz] = [r_z]

is applied by a bordered solve: with w = A^-1 r_u and G = A^-1 E, du = w - G y where the dense
(s + m) system [[I + Kss G_S, -B], [-L G_S, Kzz]] [y, dz] = [Kss w_S, r_z - L w_S] gives y, dz.
Every iteration thus costs a back-substitution and a mat-vec with A on top of the condensed
iteration's small work. ``bench/bench_transient.py`` builds its naive loop (refactorising in every
iteration) on this class, and the tests check that both formulations give the same steps.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from app.transient.coupled import CoupledSystem


class FullSpaceSystem(CoupledSystem):
    """:class:`CoupledSystem` iterating on (du, dz) instead of the condensed (g, dz)."""

    def _unknowns_local(self) -> int:
        return self.n_fe + self.m_local

    def _condense(self) -> None:
        pass            # iterates on du itself: no contact-free solution needed

    def _initial_guess(self, dz: np.ndarray) -> None:
        X = self.X.array
        X[:] = 0.0
        if self.m_local:
            X[self.n_fe:] = dz

    def _split(self, x: np.ndarray):
        n = self.n_fe
        if self.comm.size == 1:
            dz = np.array(x[n:])
        else:
            dz = self.comm.bcast(np.array(x[n:]) if self.comm.rank == 0 else None, root=0)
        return (np.array(x[:n]) if self.fe is not None else None), dz, None

    def _residual_callback(self, snes, X, R) -> None:
        self._evaluate(X)
        out = R.array
        r = None
        if self.fe is not None:
            r, du = self._r, self._du
            x_fe = X.array_r[: self.n_fe]
            if x_fe.any():
                du.array_w[:] = x_fe
                self.op.full.mult(du, r)
                r.axpy(1.0, self._r0)
            else:
                self._r0.copy(r)
        _, _, r_z = self._contact_terms(r)
        if r is not None:
            self.fe.zero_constrained(r)
            out[: self.n_fe] = r.array_r
        if self.m_local:
            out[self.n_fe:] = r_z

    def _set_jacobian(self, Kss, B, L, Kzz) -> None:
        s_count = self.contact_global.size
        G_S = self._contact_block()
        Z = np.block([[np.eye(s_count) + Kss @ G_S, -B], [-L @ G_S, Kzz]])
        self._Kss, self._B, self._L, self._Kzz = Kss, B, L, Kzz
        self._Z_lu = scipy.linalg.lu_factor(Z, check_finite=True) if Z.size else None

    def apply_inverse(self, x: np.ndarray, y: np.ndarray) -> None:
        n, s_count = self.n_fe, self.contact_global.size
        _, r_z, _ = FullSpaceSystem._split(self, x)
        if self.fe is not None:
            self._tmp.array_w[:] = x[:n]
            self.op.solve(self._tmp, self._tmp2)
            w = self._tmp2.array_r.copy()
            w_S = self._gather_S(w) if s_count else np.zeros(0)
        else:
            w, w_S = np.zeros(0), np.zeros(0)
        if self._Z_lu is not None:
            rhs = np.concatenate([self._Kss @ w_S, r_z - self._L @ w_S])
            sol = scipy.linalg.lu_solve(self._Z_lu, rhs)
            y_contact, dz = sol[:s_count], sol[s_count:]
        else:
            y_contact, dz = np.zeros(0), np.zeros(0)
        if self.fe is not None:
            y[:n] = w - self.op.columns @ y_contact if s_count else w
        if self.m_local:
            y[n:] = dz

    def apply_jacobian(self, x: np.ndarray, y: np.ndarray) -> None:
        n, s_count = self.n_fe, self.contact_global.size
        _, x_z, _ = FullSpaceSystem._split(self, x)
        if self.fe is not None:
            self._tmp.array_w[:] = x[:n]
            self.op.constrained.mult(self._tmp, self._tmp2)
            y_u = self._tmp2.array_r.copy()
            x_S = self._gather_S(x[:n]) if s_count else np.zeros(0)
            if s_count:
                local = slice(self._S_offset, self._S_offset + self.contact_local.size)
                y_u[self.contact_local] += (self._Kss @ x_S + self._B @ x_z)[local]
            y[:n] = y_u
        else:
            x_S = np.zeros(0)
        if self.m_local:
            y[n:] = self._L @ x_S + self._Kzz @ x_z
