"""The eigensolver set-up shared by the modal analyses (app/modal.py, app/fe/cyclic.py)."""

from __future__ import annotations

import math

import numpy as np
from slepc4py import SLEPc


def shift_invert_solver(comm, K, M, nev: int, target_Hz: float, prefix: str) -> SLEPc.EPS:
    """A Krylov-Schur solver of K x = omega^2 M x for the ``nev`` pairs nearest ``target_Hz`` [Hz]: shift-invert
    about omega^2 with a MUMPS LU, tolerance 1e-10; options under ``prefix`` (PETSc options database) applied.
    Not solved yet; the caller destroys it."""
    eps = SLEPc.EPS().create(comm)
    eps.setOptionsPrefix(prefix)
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setDimensions(nev=nev)
    eps.setTarget((2 * math.pi * target_Hz) ** 2)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
    eps.setTolerances(tol=1e-10, max_it=200)
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    ksp = st.getKSP()
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    eps.setFromOptions()
    return eps


def symmetric_factor(A, prefix: str):
    """A KSP (preonly) holding MUMPS's LDL^T factorisation of the symmetric (possibly indefinite) ``A``, set up; options
    under ``prefix`` applied. Why LDL^T: K, and K - sigma M, are symmetric but indefinite (the potential DOFs' block
    is negative), so a Cholesky factor does not exist; MUMPS's symmetric indefinite factorisation (SYM = 2, what PETSc
    asks for with PCCHOLESKY on a matrix not flagged positive definite) stores half the entries of an LU, so each
    solve, which streams the factor from memory, reads half as much (BENCHMARKS.md, issue 27). The caller destroys
    it; PETSc.Error from the factorisation propagates."""
    from petsc4py import PETSc

    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    A.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("cholesky")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.setFromOptions()
    ksp.setUp()
    return ksp


def block_shift_invert(factor, M, sigma: float, wanted, block: int = 24, max_dim: int = 480, tol: float = 1e-10,
                       seed: int = 27):
    """Eigenpairs of K x = lambda M x nearest ``sigma`` [rad^2/s^2] by a block Krylov subspace of the shift-invert
    operator A = (K - sigma M)^-1 M, with Rayleigh-Ritz in the M inner product. ``factor``: the factored
    K - sigma M (a PETSc factor matrix; its held rows and columns zeroed, 1 on the diagonal), ``M`` with the same
    rows and columns zeroed. ``wanted(lambdas)``: given the Ritz eigenvalues ordered by distance from sigma (nearest
    first), how many of the nearest must be converged. Returns (lambdas, X): the ``wanted`` pairs nearest sigma, X
    the owned rows of M-orthonormal eigenvectors (one column each).

    Why a block method: each step applies A to ``block`` vectors at once, one MatMatSolve on the factor (MUMPS's
    dense right-hand sides), where a one-vector Krylov method (SLEPc's Krylov-Schur) pays a whole pass over the
    factor per vector: about 10 times the cost per vector on the motor's stator (BENCHMARKS.md, issue 27).
    Each step adds the M-orthogonalised images of the last block (classical Gram-Schmidt twice); Rayleigh-Ritz with
    H = V^T M A V, which is symmetric because A is M-self-adjoint. A pair converges when its residual
    ||A x - theta x||_M <= tol |theta| (theta = 1 / (lambda - sigma)), SLEPc's relative test on the transformed
    problem, computed from the stored images A V (no extra solve). Reaching ``max_dim`` columns, the basis restarts
    from the Ritz vectors nearest sigma (thick restart). The start block is random with a fixed seed and drawn over
    the global numbering (the same on any partition)."""
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = M.getComm().tompi4py()
    lo, hi = M.getOwnershipRange()
    n_local, n_global = hi - lo, M.getSize()[0]

    def dense(values: np.ndarray):
        mat = PETSc.Mat().createDense(((n_local, n_global), (PETSc.DECIDE, values.shape[1])),
                                      array=np.asfortranarray(values), comm=comm)
        mat.assemble()
        return mat

    def times_M(values: np.ndarray) -> np.ndarray:
        x = dense(values)
        y = M.matMult(x)
        out = np.array(y.getDenseArray(readonly=True))
        x.destroy()
        y.destroy()
        return out

    def apply(values: np.ndarray) -> np.ndarray:
        rhs = dense(times_M(values))
        solution = rhs.duplicate()
        factor.matSolve(rhs, solution)
        out = np.array(solution.getDenseArray(readonly=True))
        rhs.destroy()
        solution.destroy()
        return out

    def gram(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return comm.allreduce(a.T @ b, op=MPI.SUM)

    V = np.zeros((n_local, max_dim), order="F")        # M-orthonormal basis
    MV = np.zeros_like(V)                              # M V
    AV = np.zeros_like(V)                              # A V
    H = np.zeros((max_dim, max_dim))                   # V^T M A V
    m = 0

    def m_norms(W: np.ndarray) -> np.ndarray:
        return np.sqrt(np.abs(comm.allreduce(np.einsum("ij,ij->j", W, times_M(W)), op=MPI.SUM)))

    def project(W: np.ndarray) -> np.ndarray:
        """W less its M-projection on V, classical Gram-Schmidt twice (Kahan's "twice is enough")."""
        for _ in range(2):
            W = W - V[:, :m] @ gram(MV[:, :m], W)
        return W

    def append(W: np.ndarray) -> int:
        """M-orthonormalise W against V and itself and append it to V; a column whose part outside V is below
        1e-10 of its M-norm, or the near-dependent directions among the columns (the Gram matrix of the normalised
        columns, eigenvalues below 1e-8), are dropped. Returns how many columns were appended."""
        nonlocal m
        before = m_norms(W)
        W = project(W)
        after = m_norms(W)
        live = after > 1e-10 * before
        W = W[:, live] / after[live]
        d, U = np.linalg.eigh(gram(W, times_M(W)))
        keep = d > 1e-8
        W = project((W @ U[:, keep]) / np.sqrt(d[keep]))
        d, U = np.linalg.eigh(gram(W, times_M(W)))     # near the identity now: the second pass
        W = (W @ U) / np.sqrt(d)
        k = min(W.shape[1], max_dim - m)
        V[:, m:m + k] = W[:, :k]
        MV[:, m:m + k] = times_M(W[:, :k])
        m += k
        return k

    rng = np.random.default_rng(seed)
    start = rng.standard_normal((n_global, block))[lo:hi]
    # A applied once: the start lies in A's range (no part in the massless or held DOFs' directions)
    first = apply(start)
    append(first)
    done = 0                                           # columns of V whose images are in AV and H
    last_start = 0                                     # the newest block of V: its images make the next block
    while True:
        AV[:, done:m] = apply(V[:, done:m])
        H[:m, done:m] = gram(MV[:, :m], AV[:, done:m])
        H[done:m, :done] = H[:done, done:m].T
        done = m
        theta, S = np.linalg.eigh(0.5 * (H[:m, :m] + H[:m, :m].T))
        order = np.argsort(-np.abs(theta))
        theta, S = theta[order], S[:, order]
        lambdas = sigma + 1.0 / theta
        k = min(int(wanted(lambdas)), m)
        X, AX = V[:, :m] @ S[:, :k], AV[:, :m] @ S[:, :k]
        R = AX - X * theta[:k]
        residual = m_norms(R)
        if k > 0 and np.all(residual <= tol * np.abs(theta[:k])):
            return lambdas[:k], X
        if m + block > max_dim:
            # thick restart: the Ritz vectors nearest sigma (twice the wanted, at most half the room) and their images;
            # the next directions: the residuals of those not converged yet
            keep = min(m, max(2 * k, block), max_dim // 2)
            Xk, AXk = V[:, :m] @ S[:, :keep], AV[:, :m] @ S[:, :keep]
            V[:, :keep], AV[:, :keep] = Xk, AXk
            MV[:, :keep] = times_M(Xk)
            H[:keep, :keep] = np.diag(theta[:keep])
            m = done = keep
            R = AXk - Xk * theta[:keep]
            norms = m_norms(R)
            open_ = np.flatnonzero(norms > tol * np.abs(theta[:keep]))[:block]
            last_start = keep
            added = append(R[:, open_]) if open_.size else 0
        else:
            newest = AV[:, last_start:m]
            last_start = m
            added = append(newest)
        if added == 0:
            # nothing new (the subspace is invariant under A): widen it with a fresh random block
            fresh = apply(rng.standard_normal((n_global, block))[lo:hi])
            if append(fresh) == 0:
                raise RuntimeError("block shift-invert: no new direction")
