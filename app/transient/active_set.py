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
dense product. ``active_only=False`` keeps all s DOFs (the previous dense step, the tests' reference), and so
does a system of at most ``DENSE_MAX`` contact DOFs (the drill's one or two), where the bookkeeping would cost
more than it saves.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
import scipy.sparse
from numba import njit

#: up to this many contact DOFs the Newton matrices stay dense (scipy.sparse's overhead per call, ~0.1 ms,
#: is then more than the dense arithmetic: the drill has 1-2 contact DOFs)
DENSE_MAX = 64


class ContactTangent:
    """Kss = d rc_S / d u_S summed over the interactions (the ``Kss`` of the Interaction protocol,
    :mod:`app.transient.interactions`): each adds its block with ``Kss += block`` (scipy sparse, or a
    dense s x s array). Held dense for s <= DENSE_MAX, sparse above; ``matrix()`` gives the sum."""

    def __init__(self, s_count: int):
        self.shape = (s_count, s_count)
        self.dense = s_count <= DENSE_MAX
        self._sum = np.zeros(self.shape) if self.dense else None

    def __iadd__(self, block):
        if self.dense:
            self._sum += block.toarray() if scipy.sparse.issparse(block) else block
            return self
        block = block.tocsr() if scipy.sparse.issparse(block) else scipy.sparse.csr_matrix(np.asarray(block))
        self._sum = block if self._sum is None else self._sum + block
        return self

    @property
    def empty(self) -> bool:
        """No interaction added a nonzero entry."""
        if self.dense:
            return not self._sum.any()
        return self._sum is None or self._sum.count_nonzero() == 0

    def matrix(self):
        """The sum: a dense array (s <= DENSE_MAX) or a CSR matrix."""
        if self._sum is None:
            return scipy.sparse.csr_matrix(self.shape)
        return self._sum

    def toarray(self) -> np.ndarray:
        return self._sum if self.dense else self.matrix().toarray()

    def __matmul__(self, other):
        return self.matrix() @ other


class CondensedJacobian:
    """The Newton matrix J of one iterate, factorised on its active set."""

    def __init__(self, G: np.ndarray, Kss, B: np.ndarray, L: np.ndarray, Kzz: np.ndarray, active_only: bool = True):
        """``G``: G_SS (s x s, dense); ``Kss``: d rc_S / d u_S (s x s, dense array or scipy sparse);
        ``B`` (s x m), ``L`` (m x s), ``Kzz`` (m x m) dense."""
        s_count, m = G.shape[0], Kzz.shape[0]
        self.s_count, self.m = s_count, m
        if isinstance(Kss, ContactTangent):
            Kss = Kss.matrix()
        # the all-DOF dense step: the reference, and the cheapest for a few contact DOFs
        self.reference = not active_only or s_count <= DENSE_MAX
        if self.reference:
            if scipy.sparse.issparse(Kss):
                Kss = Kss.toarray()
            self.active = np.arange(s_count)
            self.inactive = np.zeros(0, dtype=int)
            Z = self.Z = np.empty((s_count + m, s_count + m))      # [[-(I + Kss G), B], [-L G, Kzz]]
            Z[:s_count, :s_count] = -(np.eye(s_count) + Kss @ G)
            Z[:s_count, s_count:] = B
            Z[s_count:, :s_count] = -L @ G
            Z[s_count:, s_count:] = Kzz
            self._lu = lu_factor(self.Z) if self.Z.size else None
            return
        K = Kss.tocsr() if scipy.sparse.issparse(Kss) else scipy.sparse.csr_matrix(Kss)
        K.eliminate_zeros()
        rows = np.diff(K.indptr) > 0
        cols = np.zeros(s_count, dtype=bool)
        cols[K.indices] = True
        active = rows | cols | (B != 0.0).any(axis=1) | (L != 0.0).any(axis=0)
        A = self.active = np.flatnonzero(active)
        self.inactive = np.flatnonzero(~active)
        K_AA = K[A][:, A]
        self.G_A = G[A]                                 # |A| x s: the active DOFs' rows
        G_AA = self.G_A[:, A]
        if K_AA.nnz > 0.25 * A.size * A.size:
            K_AA = K_AA.toarray()
        self.K_AA = K_AA
        self.B_A = B[A]
        self.L_A = L[:, A]
        Z = np.empty((A.size + m, A.size + m))
        Z[:A.size, :A.size] = -np.asarray(K_AA @ G_AA)
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
            return lu_solve(self._lu, x) if self._lu is not None else np.array(x)
        A, I, s_count = self.active, self.inactive, self.s_count
        y = np.empty_like(x)
        x_g, x_z = x[:s_count], x[s_count:]
        y[I] = -x_g[I]
        rhs = np.concatenate([x_g[A], x_z])
        coupling = self._open_coupling(x_g[I]) if I.size else None
        if coupling is not None:
            rhs[:A.size] -= self.K_AA @ coupling
            rhs[A.size:] -= self.L_A @ coupling
        sol = lu_solve(self._lu, rhs) if self._lu is not None else rhs
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


class RigidJacobian:
    """The Newton matrix of a step without FE contact force: every contact DOF open, J = [[-I, 0], [0, Kzz]]."""

    def __init__(self, s_count: int, Kzz: np.ndarray):
        self.s_count = s_count
        self.active = np.zeros(0, dtype=int)
        self.inactive = np.arange(s_count)
        self.Kzz = Kzz
        self._lu = lu_factor(Kzz) if Kzz.size else None

    active_count = 0

    def solve(self, x: np.ndarray) -> np.ndarray:
        y = np.empty_like(x)
        y[:self.s_count] = -x[:self.s_count]
        if self._lu is not None:
            y[self.s_count:] = lu_solve(self._lu, x[self.s_count:])
        return y

    def apply(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([-x[:self.s_count], self.Kzz @ x[self.s_count:]])


def lu_factor(a: np.ndarray):
    """``scipy.linalg.lu_factor(a, check_finite=True)`` for float64 (the same LAPACK getrf, the same errors and
    warning) without its per-call dispatch."""
    if a.dtype != np.float64:
        return scipy.linalg.lu_factor(a, check_finite=True)
    if not np.isfinite(a).all():
        raise ValueError("array must not contain infs or NaNs")
    lu, piv, info = _GETRF(a)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal getrf (lu_factor)")
    if info > 0:
        warnings.warn(f"Diagonal number {info} is exactly zero. Singular matrix.", scipy.linalg.LinAlgWarning,
                      stacklevel=2)
    return lu, piv


def lu_solve(lu_and_piv, b: np.ndarray) -> np.ndarray:
    """``scipy.linalg.lu_solve(lu_and_piv, b, check_finite=False)`` for float64 (the same LAPACK getrs) without its
    per-call dispatch, which costs more than a solve of the few unknowns here."""
    lu, piv = lu_and_piv
    if lu.dtype != np.float64 or b.dtype != np.float64:
        return scipy.linalg.lu_solve(lu_and_piv, b, check_finite=False)
    x, info = _GETRS(lu, piv, b)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal getrs (lu_solve)")
    return x


_GETRS = scipy.linalg.lapack.dgetrs
_GETRF = scipy.linalg.lapack.dgetrf


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
