"""The free coordinates of a reduced model in its own modes (issue 27): q_F = Phi x_F, Phi the generalized
eigenvectors of (K_FF, M_FF) (the free coordinates: interface and modal ones; the prescribed inputs stay), so
M_FF = I and K_FF = diag(omega^2) in x. The compiled loop (app/reduced/kernel.py) then forms the contact-free
increment with one product by K_eff^-1 instead of four dense products (M, C, K, K_eff^-1): C is not diagonal
(the material quality factors add beta_j K_j per region), but C_FF y = (K_eff y - c_M y - c_K Lambda y) / c_C
needs no product of its own.

The price: a site row, sparse on the interface coordinates, becomes dense on x. So a model goes to x only when
its site rows are few against its free coordinates (the drill: 2 rows, 101 free coordinates; not the motor's
1 536 rows on 221): :func:`free_modes` decides.

The engine (app/reduced/engine.py) runs the loop's records in x throughout (state, checkpoints, sample, charge,
site rows, loads), so where a run is split into calls does not change it; a checkpoint says which coordinates
its state is in (:data:`RECORD_KEY`), and a state of the other kind is converted on reading. The model as built
stays for the checkpoint's model file, the warm-start checks and the field output (its vertex and derived bases
are large: the frames are mapped back to q instead, one small product per frame).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg

#: a model goes to its free modes when its site rows are at most this fraction of its free coordinates (each row
#: then costs a dense dot product of nf per use, against the three dense nf x nf products it saves per step)
ROWS_PER_FREE = 0.25
#: the checkpoint record's key, and its values: the state in the free modes, or in the model's own coordinates
RECORD_KEY = "coordinates"
FREE_MODES = "free_modes"
PHYSICAL = "physical"


@dataclass(frozen=True)
class FreeModes:
    """q = T x with T = I on the inputs and Phi on the free coordinates; T^-1 = Phi^T M_FF there."""

    free: np.ndarray          # (nf,) the free coordinates' positions
    phi: np.ndarray           # (nf, nf)
    phi_inverse: np.ndarray   # (nf, nf)
    omega2: np.ndarray        # (nf,) the eigenvalues [rad^2/s^2]

    def to_modes(self, q: np.ndarray) -> np.ndarray:
        """x of physical coordinates q (n,)."""
        x = np.array(q, dtype=float)
        x[self.free] = self.phi_inverse @ np.asarray(q, dtype=float)[self.free]
        return x

    def to_physical(self, x: np.ndarray) -> np.ndarray:
        """q of x: (n,) or (n, columns)."""
        q = np.array(x, dtype=float)
        q[self.free] = self.phi @ np.asarray(x, dtype=float)[self.free]
        return q

    def matrix(self, n: int) -> np.ndarray:
        """T (n x n)."""
        T = np.eye(n)
        T[np.ix_(self.free, self.free)] = self.phi
        return T


def free_modes(model, free: np.ndarray, comm=None) -> FreeModes | None:
    """The free modes of ``model`` (a :class:`app.reduced.model.ReducedModel`) on the coordinates ``free``, or
    None when its site rows are too many for them (:data:`ROWS_PER_FREE`). With ``comm``, rank 0's eigenvectors
    on every rank (the ranks step the same replicated state)."""
    if free.size == 0 or model.site_rows.shape[0] > ROWS_PER_FREE * free.size:
        return None
    modes = modes_of(model.K, model.M, free) if comm is None or comm.rank == 0 else None
    return modes if comm is None or comm.size == 1 else comm.bcast(modes, root=0)


def modes_of(K: np.ndarray, M: np.ndarray, free: np.ndarray) -> FreeModes:
    """The generalized eigenvectors of (K_FF, M_FF), M-orthonormal."""
    KFF = K[np.ix_(free, free)]
    MFF = M[np.ix_(free, free)]
    omega2, phi = scipy.linalg.eigh(0.5 * (KFF + KFF.T), 0.5 * (MFF + MFF.T))
    return FreeModes(np.asarray(free, dtype=np.int64), phi, phi.T @ MFF, omega2)


def operators_in_modes(K: np.ndarray, M: np.ndarray, C: np.ndarray, modes: FreeModes):
    """(T^T K T, T^T M T, T^T C T), symmetric, with M_FF = I and K_FF = diag(omega^2) exactly (the round-off off the
    diagonal dropped: the loop takes its diagonal path only for exact zeros)."""
    T = modes.matrix(K.shape[0])
    F = modes.free

    def congruent(A, diagonal):
        out = T.T @ A @ T
        out = 0.5 * (out + out.T)
        if diagonal is not None:
            out[np.ix_(F, F)] = np.diag(diagonal)
        return np.ascontiguousarray(out)

    return congruent(K, modes.omega2), congruent(M, np.ones(F.size)), congruent(C, None)


def rows_in_modes(R: np.ndarray, modes: FreeModes) -> np.ndarray:
    """Rows on q (anything x n) as rows on x: R T."""
    out = np.array(R, dtype=float)
    if R.size:
        out[:, modes.free] = np.asarray(R, dtype=float)[:, modes.free] @ modes.phi
    return out


def in_free_modes(model, modes: FreeModes):
    """The model in x: K, M, C by :func:`operators_in_modes`, the rows the loop and the engine's set-up read
    (sites, points, charges, translation loads) by :func:`rows_in_modes`. The field bases (vertex, derived) are
    left out (empty, (0, n)): the field output reads the model as built, with the frames mapped back to q."""
    K, M, C = operators_in_modes(model.K, model.M, model.C, modes)
    n = model.size
    return dataclasses.replace(model, K=K, M=M, C=C, charge_rows=rows_in_modes(model.charge_rows, modes),
                               translation_loads=rows_in_modes(model.translation_loads, modes),
                               sample_rows=rows_in_modes(model.sample_rows, modes),
                               site_rows=rows_in_modes(model.site_rows, modes),
                               vertex_basis=np.zeros((0, n)), derived_basis=np.zeros((0, n)))
