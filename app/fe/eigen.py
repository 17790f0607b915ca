"""The eigensolver set-up shared by the modal analyses (app/modal.py, app/fe/cyclic.py)."""

from __future__ import annotations

import math

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
