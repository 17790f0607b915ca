"""Newton on the active set of the condensed contact step (:mod:`app.transient.coupled`).

The condensed Newton matrix on the contact forces g (s of them) and the rigid increments dz (m) is

    J = [[-(I + Kss G), B], [-L G, Kzz]],    G = E^T K_eff^-1 E (s x s),

Kss, B, L the contact tangents. A contact DOF whose row and column of Kss, row of B and column of L
vanish (no quadrature point of a facet it belongs to penetrates: an *open* DOF) has the row -e_i in
J, so with I the open DOFs and A the others (closed, or on a facet that is closing)

    y_I = -x_I,
    [[-(I + K_AA G_AA), B_A], [-L_A G_AA, Kzz]] [y_A, y_z] = [x_A - K_AA G_AI x_I, x_z - L_A G_AI x_I]

solves J y = x exactly: a dense system of |A| + m unknowns instead of s + m. The x_I terms are the
update of DOFs that carried force at the previous iterate and have opened since (their force must go
to zero: y_I = -x_I = g_I - rc_I = g_I), so a set that changes inside the iteration is carried
exactly; DOFs that close in this iteration join A at the next evaluation (semi-smooth Newton). The
active set is read from the tangent's structure, not from a gap test, so the result is the all-DOF
Newton's step to round-off. On the motor 86-89 % of the contact points are open at any instant.

K_AA is sparse (facet-local coupling, ~30-60 entries per row): K_AA G_AA is formed as a sparse times
dense product. ``active_only=False`` keeps all s DOFs (the previous dense step, the tests' reference).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse
from numba import njit


class ContactTangent:
    """Kss = d rc_S / d u_S summed over the interactions (the ``Kss`` of the Interaction protocol,
    :mod:`app.transient.interactions`): each adds its block with ``Kss += block`` (scipy sparse, or a
    dense s x s array); ``tocsr()`` gives the sum."""

    def __init__(self, s_count: int):
        self.shape = (s_count, s_count)
        self._sum = None

    def __iadd__(self, block):
        block = block.tocsr() if scipy.sparse.issparse(block) else scipy.sparse.csr_matrix(np.asarray(block))
        self._sum = block if self._sum is None else self._sum + block
        return self

    def tocsr(self) -> scipy.sparse.csr_matrix:
        return self._sum if self._sum is not None else scipy.sparse.csr_matrix(self.shape)

    def toarray(self) -> np.ndarray:
        return self.tocsr().toarray()

    def __matmul__(self, other):
        return self.tocsr() @ other


class CondensedJacobian:
    """The Newton matrix J of one iterate, factorised on its active set."""

    def __init__(self, G: np.ndarray, Kss, B: np.ndarray, L: np.ndarray, Kzz: np.ndarray, active_only: bool = True):
        """``G``: G_SS (s x s, dense); ``Kss``: d rc_S / d u_S (s x s, dense array or scipy sparse);
        ``B`` (s x m), ``L`` (m x s), ``Kzz`` (m x m) dense."""
        s_count, m = G.shape[0], Kzz.shape[0]
        self.s_count, self.m = s_count, m
        if isinstance(Kss, ContactTangent):
            Kss = Kss.tocsr()
        if not active_only and scipy.sparse.issparse(Kss):
            Kss = Kss.toarray()             # the reference: the dense products of the all-DOF step
        sparse = scipy.sparse.issparse(Kss)
        if active_only:
            if sparse:
                K = Kss.tocsr()
                K.eliminate_zeros()
                rows = np.diff(K.indptr) > 0
                cols = np.zeros(s_count, dtype=bool)
                cols[K.indices] = True
            else:
                nonzero = Kss != 0.0
                rows, cols = nonzero.any(axis=1), nonzero.any(axis=0)
            active = rows | cols | (B != 0.0).any(axis=1) | (L != 0.0).any(axis=0)
            self.active = np.flatnonzero(active)
            self.inactive = np.flatnonzero(~active)
        else:
            self.active = np.arange(s_count)
            self.inactive = np.zeros(0, dtype=int)
        A = self.active
        all_active = A.size == s_count
        if sparse:
            K_AA = Kss.tocsr()[A][:, A] if not all_active else Kss.tocsr()
        else:
            K_AA = Kss[np.ix_(A, A)] if not all_active else Kss
        self.G_A = G[A] if not all_active else G                  # |A| x s: rows of the active DOFs
        G_AA = self.G_A[:, A] if not all_active else G
        self.reference = not active_only
        if active_only and not sparse and A.size > 64:
            density = np.count_nonzero(K_AA) / K_AA.size
            if density < 0.25:
                K_AA = scipy.sparse.csr_matrix(K_AA)
                sparse = True
        self.K_AA = K_AA
        self.B_A = B[A]
        self.L_A = L[:, A]
        KG = K_AA @ G_AA
        KG = np.asarray(KG)
        Z = np.empty((A.size + m, A.size + m))
        Z[:A.size, :A.size] = -KG
        Z[np.arange(A.size), np.arange(A.size)] -= 1.0
        Z[:A.size, A.size:] = self.B_A
        Z[A.size:, :A.size] = -(self.L_A @ G_AA)
        Z[A.size:, A.size:] = Kzz
        self.Z = Z
        self._lu = scipy.linalg.lu_factor(Z, check_finite=True) if Z.size else None

    @property
    def active_count(self) -> int:
        return int(self.active.size)

    def _open_coupling(self, x_I: np.ndarray):
        """G_AI x_I (the opened DOFs' forces seen at the active DOFs), None if x_I = 0."""
        nonzero = np.flatnonzero(x_I)
        if not nonzero.size:
            return None
        return self.G_A[:, self.inactive[nonzero]] @ x_I[nonzero]

    def solve(self, x: np.ndarray) -> np.ndarray:
        """y = J^-1 x (x = (x_g, x_z))."""
        if self.reference:
            return scipy.linalg.lu_solve(self._lu, x) if self._lu is not None else np.array(x)
        A, I, s_count = self.active, self.inactive, self.s_count
        y = np.empty_like(x)
        x_g, x_z = x[:s_count], x[s_count:]
        y[I] = -x_g[I]
        rhs = np.concatenate([x_g[A], x_z])
        coupling = self._open_coupling(x_g[I]) if I.size else None
        if coupling is not None:
            rhs[:A.size] -= self.K_AA @ coupling
            rhs[A.size:] -= self.L_A @ coupling
        sol = scipy.linalg.lu_solve(self._lu, rhs) if self._lu is not None else rhs
        y[A] = sol[:A.size]
        y[s_count:] = sol[A.size:]
        return y

    def apply(self, x: np.ndarray) -> np.ndarray:
        """y = J x."""
        if self.reference:
            return self.Z @ x
        A, I, s_count = self.active, self.inactive, self.s_count
        x_g, x_z = x[:s_count], x[s_count:]
        y = np.empty_like(x)
        y[I] = -x_g[I]
        nonzero = np.flatnonzero(x_g)
        t = self.G_A[:, nonzero] @ x_g[nonzero] if nonzero.size else np.zeros(A.size)
        y[A] = -x_g[A] - np.asarray(self.K_AA @ t).reshape(-1) + self.B_A @ x_z
        y[s_count:] = -(self.L_A @ t) + self.Z[A.size:, A.size:] @ x_z
        return y


@njit(cache=True)
def subtract_rows(out, rows_t, index, coefficient):
    """out -= sum_k coefficient[k] * rows_t[index[k], :], in cache-sized chunks of ``out`` (one pass
    over the selected rows of ``rows_t``, no copy of them)."""
    n = out.size
    chunk = 2048
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        for k in range(index.size):
            c = coefficient[k]
            row = rows_t[index[k]]
            for i in range(start, stop):
                out[i] -= c * row[i]
