"""The block shift-invert eigensolver (app/fe/eigen.py block_shift_invert) against a closed form.

The problem: two identical fixed-fixed chains of n unit springs and masses (K = tridiag(-1, 2, -1) per chain,
M = 2 I), side by side and uncoupled, so every eigenvalue is double: lambda_k = 2 sin^2(k pi / (2 (n + 1))), k = 1..n
(the discrete string). Plus, as in the Craig-Bampton model, DOFs the solver must leave out: two held DOFs
(row and column zeroed, 1 on K's diagonal, 0 on M's) and, between the chains, "massless" DOFs with a spring to
ground and none to the chains (M's row zero), which have no finite eigenvalue. Checked: the 12 lowest pairs about
0 (the factor is positive definite there) and the 4 nearest a shift between lambda_5 and lambda_6 (indefinite
factor: MUMPS's LDL^T with pivoting), each returned pair:

* its eigenvalue against the closed form (1e-11 relative: the solver converges the residual to 1e-10 relative to
  theta = 1 / (lambda - sigma), and a symmetric problem's eigenvalue error is of the order of the residual squared
  over the gap; the closed form is exact up to round-off, 1e-15);
* both copies of each double eigenvalue are found (a one-vector method can miss a multiple eigenvalue; the block
  of 8 spans it), and the vectors are M-orthonormal (1e-10) and vanish on the held and massless DOFs.

A wrong sign of the shift moves the eigenvalues by O(1); a Rayleigh-Ritz matrix in the Euclidean inner product
(V^T A V for V^T M A V) never converges (the solver gives up after its restarts).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

N_CHAIN = 300         # masses per chain
N_MASSLESS = 6        # grounded massless DOFs between the chains
CHAIN_MASS = 2.0      # not 1: the M inner product differs from the Euclidean one


def _problem():
    from mpi4py import MPI
    from petsc4py import PETSc

    n = 2 * N_CHAIN + N_MASSLESS + 2
    chains = [np.arange(N_CHAIN), N_CHAIN + N_MASSLESS + np.arange(N_CHAIN)]
    massless = N_CHAIN + np.arange(N_MASSLESS)
    held = np.array([n - 2, n - 1])
    K = PETSc.Mat().createAIJ((n, n), nnz=3, comm=MPI.COMM_WORLD)
    M = PETSc.Mat().createAIJ((n, n), nnz=3, comm=MPI.COMM_WORLD)
    lo, hi = K.getOwnershipRange()
    for chain in chains:
        for j, row in enumerate(chain):
            if lo <= row < hi:
                K.setValue(row, row, 2.0)
                M.setValue(row, row, CHAIN_MASS)
                if j > 0:
                    K.setValue(row, chain[j - 1], -1.0)
                if j < N_CHAIN - 1:
                    K.setValue(row, chain[j + 1], -1.0)
    for row in massless:
        if lo <= row < hi:
            K.setValue(row, row, 3.0)
            M.setValue(row, row, 0.0)
    for row in held:
        if lo <= row < hi:
            K.setValue(row, row, 5.0)       # before clamping: a stiffness that clamping replaces by 1
            M.setValue(row, row, 1.0)
    K.assemble()
    M.assemble()
    owned_held = held[(held >= lo) & (held < hi)].astype(PETSc.IntType)
    K.zeroRowsColumns(owned_held, 1.0)
    M.zeroRowsColumns(owned_held, 0.0)
    return K, M, massless, held


def _exact() -> np.ndarray:
    k = np.arange(1, N_CHAIN + 1)
    return np.repeat(4 / CHAIN_MASS * np.sin(k * math.pi / (2 * (N_CHAIN + 1))) ** 2, 2)


def _solve(sigma: float, count: int):
    from petsc4py import PETSc

    from app.fe.eigen import block_shift_invert, symmetric_factor

    K, M, massless, held = _problem()
    shifted = K.copy()
    shifted.axpy(-sigma, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    held_rows = [r for r in held if shifted.getOwnershipRange()[0] <= r < shifted.getOwnershipRange()[1]]
    for row in held_rows:      # clamped: K's diagonal 1 stays 1 after the shift (M is 0 there)
        assert shifted.getValue(row, row) == 1.0
    ksp = symmetric_factor(shifted, "test_block_eigen_")
    lambdas, X = block_shift_invert(ksp.getPC().getFactorMatrix(), M, sigma, lambda lams: count, block=8)
    lo, hi = M.getOwnershipRange()
    # M-orthonormality of the returned vectors (owned rows; the sum over ranks)
    from mpi4py import MPI

    Xm = PETSc.Mat().createDense(((hi - lo, M.getSize()[0]), (PETSc.DECIDE, X.shape[1])),
                                 array=np.asfortranarray(X), comm=M.getComm())
    Xm.assemble()
    MX = M.matMult(Xm)
    gram = MPI.COMM_WORLD.allreduce(X.T @ MX.getDenseArray(readonly=True), op=MPI.SUM)
    left_out = np.concatenate([massless, held])
    mine = left_out[(left_out >= lo) & (left_out < hi)] - lo
    leak = MPI.COMM_WORLD.allreduce(float(np.abs(X[mine]).max(initial=0.0)), op=MPI.MAX)
    for obj in (Xm, MX, ksp, shifted, K, M):
        obj.destroy()
    return np.sort(lambdas), gram, leak


@pytest.mark.mpi
def test_lowest_pairs_of_two_identical_chains():
    lambdas, gram, leak = _solve(0.0, 24)
    np.testing.assert_allclose(lambdas, _exact()[:24], rtol=1e-11, atol=0)
    assert np.abs(gram - np.eye(24)).max() <= 1e-10
    assert leak <= 1e-10


@pytest.mark.mpi
def test_pairs_nearest_an_interior_shift():
    exact = _exact()
    sigma = 0.5 * (exact[9] + exact[10]) + 0.1 * (exact[10] - exact[9])   # between lambda_5 and lambda_6
    lambdas, gram, leak = _solve(sigma, 4)
    nearest = np.sort(exact[np.argsort(np.abs(exact - sigma))[:4]])
    np.testing.assert_allclose(lambdas, nearest, rtol=1e-11, atol=0)
    np.testing.assert_allclose(nearest, exact[8:12], rtol=0, atol=0)       # the two pairs on either side
    assert np.abs(gram - np.eye(4)).max() <= 1e-10
    assert leak <= 1e-10


@pytest.mark.mpi
def test_more_pairs_wanted_than_the_model_has():
    """Two chains of 6 masses have 12 finite eigenpairs; asked for 20, the solver's basis (built in A's range) stops
    at those 12 dimensions and returns the 12, exact (the closed form, 1e-11 as above), instead of failing or
    inventing pairs from the massless and held DOFs' directions (which have no finite eigenvalue): the
    fixed-interface modes of a small model with a high cutoff."""
    global N_CHAIN
    saved, N_CHAIN = N_CHAIN, 6
    try:
        lambdas, gram, leak = _solve(0.0, 20)
        exact = _exact()
    finally:
        N_CHAIN = saved
    assert lambdas.size == 12
    np.testing.assert_allclose(lambdas, exact, rtol=1e-11, atol=0)
    assert np.abs(gram - np.eye(12)).max() <= 1e-10
    assert leak <= 1e-10
