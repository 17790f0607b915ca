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
    return direct_factor(A, prefix, "cholesky")


def direct_factor(A, prefix: str, kind: str = "lu"):
    """A KSP (preonly) holding MUMPS's factorisation of ``A`` (``kind``: PETSc's PC type, "lu" or "cholesky"), set
    up, options under ``prefix`` applied. The caller destroys it."""
    from petsc4py import PETSc

    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType(kind)
    ksp.getPC().setFactorSolverType("mumps")
    ksp.setFromOptions()
    ksp.setUp()
    return ksp


def block_shift_invert(factor, M, sigma: float, wanted, block: int = 8, max_dim: int = 320, tol: float = 1e-10,
                       seed: int = 27, stats: dict | None = None, max_restarts: int = 20):
    """Eigenpairs of K x = lambda M x nearest ``sigma`` [rad^2/s^2] by a block Krylov subspace of the shift-invert
    operator A = (K - sigma M)^-1 M, with Rayleigh-Ritz in the M inner product. ``factor``: the factored
    K - sigma M (a PETSc factor matrix; its held rows and columns zeroed, 1 on the diagonal), ``M`` with the same
    rows and columns zeroed. ``wanted(lambdas)``: given the Ritz eigenvalues ordered by distance from sigma (nearest
    first), how many of the nearest must be converged. Returns (lambdas, X): those pairs, X the owned rows of
    M-orthonormal eigenvectors (one column each). ``stats`` (optional dict): gets the columns solved for, the
    subspace's final dimension, the restarts.

    Why a block method: each step applies A to ``block`` vectors at once, one MatMatSolve on the factor (MUMPS's
    dense right-hand sides), where a one-vector Krylov method (SLEPc's Krylov-Schur) pays a whole pass over the
    factor per vector: about 10 times the cost per vector on the motor's stator (BENCHMARKS.md, issue 27).

    Each step expands the basis V by the images A V_new of its newest block, M-orthogonalised against V (classical
    Gram-Schmidt twice, Kahan's "twice is enough", the first pass's coefficients those of H; then normalised and
    once more, with the block's own directions orthonormalised by an eigendecomposition of their Gram matrix,
    near-dependent ones dropped). Rayleigh-Ritz with H = V^T M A V, symmetric because A is M-self-adjoint. A Ritz
    pair (theta, x = V s) converges when its residual ||A x - theta x||_M <= tol |theta| (theta = 1 / (lambda -
    sigma)): SLEPc's relative test on the transformed problem. That residual is estimated from the newest images'
    part outside V (the block Lanczos estimate) and, when the estimate passes, computed exactly from the stored
    images A V (no extra solve). Beyond ``max_dim`` columns (and 3 times the wanted), the basis restarts from the
    Ritz vectors nearest sigma (thick restart); RuntimeError after ``max_restarts``. The start block is random with
    a fixed seed, drawn over the global numbering (the same on any partition), with A applied once (no part in the
    massless or held directions)."""
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = M.getComm().tompi4py()
    lo, hi = M.getOwnershipRange()
    n_local, n_global = hi - lo, M.getSize()[0]
    M_products = without_zeros(M)
    count = {"columns": 0, "restarts": 0}

    def dense(values: np.ndarray):
        mat = PETSc.Mat().createDense(((n_local, n_global), (PETSc.DECIDE, values.shape[1])),
                                      array=np.asfortranarray(values), comm=comm)
        mat.assemble()
        return mat

    def times_M(values: np.ndarray) -> np.ndarray:
        x = dense(values)
        y = M_products.matMult(x)
        out = np.array(y.getDenseArray(readonly=True))
        x.destroy()
        y.destroy()
        return out

    def solve(M_values: np.ndarray) -> np.ndarray:
        """K_sigma^-1 (M V), given M V."""
        count["columns"] += M_values.shape[1]
        rhs = dense(M_values)
        solution = rhs.duplicate()
        factor.matSolve(rhs, solution)
        out = np.array(solution.getDenseArray(readonly=True))
        rhs.destroy()
        solution.destroy()
        return out

    def gram(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return comm.allreduce(a.T @ b, op=MPI.SUM)

    def column_norms(W: np.ndarray, MW: np.ndarray) -> np.ndarray:
        return np.sqrt(np.abs(comm.allreduce(np.einsum("ij,ij->j", W, MW), op=MPI.SUM)))

    capacity = min(max_dim, 8 * block)
    V = np.zeros((n_local, capacity), order="F")       # M-orthonormal basis
    MV = np.zeros_like(V)                              # M V
    AV = np.zeros_like(V)                              # A V
    H = np.zeros((capacity, capacity))                 # V^T M A V
    m = 0

    def grow(columns: int) -> None:
        """Room for ``columns`` columns in V, M V, A V and H (their first m kept)."""
        nonlocal V, MV, AV, H, capacity
        if columns <= capacity:
            return
        capacity = max(columns, 2 * capacity)

        def grown(a: np.ndarray) -> np.ndarray:
            # np.zeros' pages stay unresident until written, so only the m columns copied here and those appended
            # later take memory; a concatenation with zeros wrote (made resident) every column of the capacity,
            # up to twice what is used, with the three old arrays beside the three new ones during the copy
            # (BENCHMARKS.md, "the reduced stator's build memory")
            out = np.zeros((n_local, capacity), order="F")
            out[:, :m] = a[:, :m]
            return out

        V = grown(V)            # one array at a time: the old one is freed before the next is copied
        MV = grown(MV)
        AV = grown(AV)
        H = np.pad(H, ((0, capacity - H.shape[0]), (0, capacity - H.shape[1])))

    def outside(W: np.ndarray, MW: np.ndarray, passes: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """W less its M-projection on V, ``passes`` times; M W updated alike."""
        for _ in range(passes):
            C = gram(MV[:, :m], W)
            W = W - V[:, :m] @ C
            MW = MW - MV[:, :m] @ C
        return W, MW

    def append(W: np.ndarray, MW: np.ndarray, before: np.ndarray) -> int:
        """Append the directions of W (already M-orthogonalised against V once: ``outside``; M W with it;
        ``before``: the columns' M-norms before) to V, M-orthonormal: a column whose part outside V is below
        1e-13 of its norm before is dropped, the rest normalised, M W computed afresh (the updated one has lost
        digits to cancellation), orthogonalised again and orthonormalised among themselves (the Gram matrix's
        eigendecomposition: directions of eigenvalue below 1e-8, near-dependent, dropped; then once more, the
        Gram matrix now near the identity). Returns how many columns were appended."""
        nonlocal m
        norms = column_norms(W, MW)
        live = norms > 1e-13 * before
        W = W[:, live] / norms[live]
        W, MW = outside(W, times_M(W), passes=1)      # the third pass, on the normalised columns
        for threshold in (1e-8, 0.5):
            d, U = np.linalg.eigh(gram(W, MW))
            T = U[:, d > threshold] / np.sqrt(d[d > threshold])
            W, MW = W @ T, MW @ T
        k = W.shape[1]
        grow(m + k)
        V[:, m:m + k], MV[:, m:m + k] = W, MW
        m += k
        return k

    def fresh_block() -> int:
        start = rng.standard_normal((n_global, block))[lo:hi]
        W = solve(times_M(start))
        MW = times_M(W)
        before = column_norms(W, MW)
        return append(*outside(W, MW), before)

    def iterate():
        nonlocal m
        fresh_block()
        done = 0                                       # columns of V whose images are in AV and H
        while True:
            newest = slice(done, m)
            AV[:, newest] = solve(MV[:, newest])
            H[:m, newest] = gram(MV[:, :m], AV[:, newest])
            H[newest, :done] = H[:done, newest].T
            done = m
            theta, S = np.linalg.eigh(0.5 * (H[:m, :m] + H[:m, :m].T))
            order = np.argsort(-np.abs(theta))
            theta, S = theta[order], S[:, order]
            lambdas = sigma + 1.0 / theta
            k = min(int(wanted(lambdas)), m)
            # the next directions: the newest images' part outside V; with the Ritz vectors' coefficients on the
            # newest block it is the block Lanczos estimate of their residuals
            Y = AV[:, newest]
            MY = times_M(Y)
            before = column_norms(Y, MY)
            C = H[:m, newest]                          # the first pass's coefficients V^T M Y: computed above
            W, MW = outside(Y - V[:, :m] @ C, MY - MV[:, :m] @ C, passes=1)
            G = gram(W, MW)
            S_new = S[newest, :k]
            estimate = np.sqrt(np.abs(np.einsum("ij,ik,kj->j", S_new, G, S_new)))
            if k > 0 and np.all(estimate <= tol * np.abs(theta[:k])):
                X, AX = V[:, :m] @ S[:, :k], AV[:, :m] @ S[:, :k]
                R = AX - X * theta[:k]
                if np.all(column_norms(R, times_M(R)) <= tol * np.abs(theta[:k])):
                    if stats is not None:
                        stats.update(count, dimension=m, wanted=k)
                    return lambdas[:k], X
            if m + block > max(max_dim, 3 * k + block):
                # thick restart: the Ritz vectors nearest sigma (twice the wanted) and their images; the next
                # directions: the residuals of those not converged yet
                count["restarts"] += 1
                if count["restarts"] > max_restarts:
                    raise RuntimeError(f"block shift-invert: {k} pairs not converged to {tol:g} after {max_restarts} "
                                       f"restarts ({count['columns']} vectors solved)")
                keep = min(m, max(2 * k, block))
                Xk, AXk = V[:, :m] @ S[:, :keep], AV[:, :m] @ S[:, :keep]
                V[:, :keep], AV[:, :keep] = Xk, AXk
                MV[:, :keep] = times_M(Xk)
                H[:keep, :keep] = np.diag(theta[:keep])
                m = done = keep
                R = AXk - Xk * theta[:keep]
                MR = times_M(R)
                norms = column_norms(R, MR)
                open_ = np.flatnonzero(norms > tol * np.abs(theta[:keep]))[:block]
                added = append(*outside(R[:, open_], MR[:, open_]), norms[open_]) if open_.size else 0
            else:
                added = append(W, MW, before)
            if added == 0 and fresh_block() == 0:
                # nothing new (the subspace is invariant under A) and a random block adds nothing either
                raise RuntimeError("block shift-invert: no new direction")

    rng = np.random.default_rng(seed)
    try:
        return iterate()
    finally:
        M_products.destroy()


def without_zeros(A):
    """A copy of the assembled AIJ ``A`` without its stored zeros (a mixed space's mass matrix is assembled on the
    whole u-phi pattern: its potential rows and the cross-component entries are stored zeros), for products that
    read it many times. Collective."""
    from petsc4py import PETSc

    indptr, indices, values = A.getValuesCSR()
    nonzero = values != 0.0
    kept = np.concatenate([[0], np.cumsum(nonzero, dtype=np.int64)])[indptr]       # nonzeros before each row's start
    compact_ptr = kept.astype(PETSc.IntType)
    out = PETSc.Mat().createAIJ(A.getSizes(), csr=(compact_ptr, indices[nonzero].astype(PETSc.IntType),
                                                   values[nonzero]), comm=A.getComm())
    out.assemble()
    return out
