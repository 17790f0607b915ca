"""Reduced (Craig-Bampton) transient against the full FE equations, without contact.

The drill transducer is driven from rest by U(t) = V sin(omega t) at 20.1 kHz for 1 ms with the
drill case's generalized-alpha scheme and step. The reference integrates the full FE equations (all
u-phi DOFs, the same discrete scheme: K_eff factorised once, Dirichlet rows for supports, grounded
parts and electrodes) with PETSc; the reduced model integrates the projected equations. The tip
displacement histories agree to the truncation error of the basis, which falls as modes are added.
"""

import math

import numpy as np
import pytest
from test_reduced_basis import _basis, transducer  # noqa: F401  (module fixture)

from forms.newmark import TimeScheme, acceleration, effective_weights, velocity

FREQUENCY_HZ = 20100.0
VOLTAGE_V = 100.0
DT_S = 1e-6
END_S = 1e-3
SCHEME = TimeScheme.generalized_alpha(0.5)


def _drive(t):
    w = 2 * math.pi * FREQUENCY_HZ
    return VOLTAGE_V * math.sin(w * t), VOLTAGE_V * w * math.cos(w * t), -VOLTAGE_V * w * w * math.sin(w * t)


def _fe_tip_history(model, ops, tip_global):
    """Full-order generalized-alpha integration (the FE tier's discrete equations) -> tip u_z(t)."""
    from petsc4py import PETSc

    s = SCHEME
    imap = model.W.dofmap.index_map
    lo = imap.local_range[0]
    n = imap.size_local

    def owned(local):
        local = np.asarray(local)
        return local[local < n]

    fixed = np.unique(np.concatenate([owned(model.support_dofs), owned(model.grounded_dofs)]
                                     + [owned(model.electrode_dofs[e]) for e in model.electrodes_of("ground")]))
    driven = np.unique(np.concatenate([owned(model.electrode_dofs[e]) for e in model.electrodes_of("voltage")]))
    held = np.union1d(fixed, driven).astype(np.int32)
    w_m, w_c, w_k = effective_weights(DT_S, s)
    A = ops.K.copy()
    A.scale(w_k)
    A.axpy(w_m, ops.M, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    A.axpy(w_c, ops.C, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    A.zeroRowsColumns((held + lo).astype(PETSc.IntType), 1.0)
    ksp = PETSc.KSP().create(model.comm)
    ksp.setOptionsPrefix("test_cb_fe_transient_")
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    u, v, a = (np.zeros(n) for _ in range(3))
    x, y, r, du = (A.createVecRight() for _ in range(4))
    tip_local = tip_global - lo if lo <= tip_global < lo + n else None
    history = [0.0]
    t = 0.0
    for _ in range(round(END_S / DT_S)):
        t1 = t + DT_S
        u1 = u + DT_S * v + 0.5 * DT_S**2 * a
        value, rate, second = _drive(t1)
        u1[fixed], u1[driven] = 0.0, value
        a1 = acceleration(u1, u, v, a, DT_S, s)
        v1 = velocity(a1, v, a, DT_S, s)
        r.set(0.0)
        for mat, vec in ((ops.M, (1 - s.alpha_m) * a1 + s.alpha_m * a), (ops.C, (1 - s.alpha_f) * v1 + s.alpha_f * v),
                         (ops.K, (1 - s.alpha_f) * u1 + s.alpha_f * u)):
            x.array_w[:] = vec
            mat.mult(x, y)
            r.axpy(1.0, y)
        r.array_w[held] = 0.0
        r.scale(-1.0)
        ksp.solve(r, du)
        u1 = u1 + du.array_r
        a1 = acceleration(u1, u, v, a, DT_S, s)
        v1 = velocity(a1, v, a, DT_S, s)
        u, v, a, t = u1, v1, a1, t1
        value = u[tip_local] if tip_local is not None else None
        owner = model.comm.allreduce(model.comm.rank if tip_local is not None else model.comm.size, op=min_op())
        history.append(model.comm.bcast(value, root=owner))
    for obj in (A, ksp, x, y, r, du):
        obj.destroy()
    return np.array(history)


def min_op():
    from mpi4py import MPI

    return MPI.MIN


def _reduced_tip_history(basis):
    from app.reduced.integrator import ReducedLinearStepper

    P = np.array([basis.electrode_index("hot")])

    def prescribed(t):
        value, rate, second = _drive(t)
        return np.array([value]), np.array([rate]), np.array([second])

    stepper = ReducedLinearStepper(basis, SCHEME, P, prescribed)
    state = stepper.initial_state(0.0)
    history = [state.q[0]]
    for _ in range(round(END_S / DT_S)):
        state = stepper.step(state, DT_S)
        history.append(state.q[0])
    return np.array(history)


@pytest.mark.mpi
def test_reduced_transient_tip_matches_fe_and_converges(transducer):  # noqa: F811
    from test_reduced_basis import _tip_dof

    model, ops = transducer
    tip, _ = _tip_dof(model)
    reference = _fe_tip_history(model, ops, tip)
    assert np.max(np.abs(reference)) > 1e-7        # the drive rings the transducer up (~um)
    errors = {}
    for n in (4, 8, 16, 32):
        basis = _basis(model, ops, n)
        reduced = _reduced_tip_history(basis)
        errors[n] = np.linalg.norm(reduced - reference) / np.linalg.norm(reference)
        basis.destroy()
    # issue 9: <= 1e-3 at the default basis; the error falls as modes are added. Measured on this
    # mesh: 1.7e-3, 2.3e-4, 3.8e-5, 1.5e-5 for 4, 8, 16, 32 modes (3.8e-6 for 64).
    assert errors[16] <= 1e-3, errors
    assert errors[32] < errors[8] < errors[4], errors
