"""The reduced stator's build path (app/reduced/craig_bampton.py, issue 27) against the straightforward one.

The default build factorises the clamped K once as LDL^T (MUMPS, symmetric indefinite), solves the static
(constraint) modes on it in blocks of right-hand sides, and finds the fixed-interface modes by a block shift-invert
Krylov method on the same factor (app/fe/eigen.py block_shift_invert), the enrichment by the same method on an
LDL^T of K - sigma M; the reference path (``shared_factorisation=False``) factorises with an LU, solves one
right-hand side at a time and gives SLEPc's Krylov-Schur its own factorisation, as the build did before. Checked
on the shipped motor's coarse stator (6 mm, 2 mm at the tip; 32 interface nodes, so 96 interface DOFs and 4
electrodes: two blocks of right-hand sides; the cutoff 3 x 36 065 Hz; the F(1,4) pair enriched), both paths on
the same assembled operators:

* the number of factorisations (PETSc's MatLUFactorNum and MatCholFctrNum events): 2 on the default path (the
  clamped K, the enrichment's shifted K), at least 3 on the reference (the eigensolver's own): the reuse happens;
* the basis-independent results agree: the fixed-interface and enrichment frequencies, the reduced short-circuit
  frequencies of the whole basis, the static block of K_r, M_r, C_r and of the charge rows (the static modes are
  the same vectors: the same right-hand sides, solved on an LDL^T against an LU of the same matrix), and the
  harmonic response at the drive. The modal columns themselves are not compared: an eigensolver returns a
  degenerate pair (the F(1,4) modes) in any rotation, so K_r's modal block is basis-dependent.

Tolerances: the static block is one direct solve against another of the same matrix (LDL^T in blocks of
right-hand sides against LU one at a time): measured 3.4e-14 (K), 1.1e-13 (M), 3.9e-14 (C), 3.8e-14 (charge rows)
relative to the block's largest entry (1e-12 allowed). The eigenpairs are converged to the relative residual 1e-10
on both paths (the block method's test is SLEPc's), the eigenvalues then agree to about that squared: measured
1.3e-14 (fixed-interface), 9.5e-15 (enrichment), 7.3e-12 (the reduced short-circuit spectrum) relative (1e-10
allowed). The harmonic response 0.1 % below the F(1,4) pair (zeta 0.2 %: the basis's difference amplified about
250 times): measured 3.0e-11 (interface displacements), 1.7e-11 (charges) relative (1e-8 allowed). The
projection: 7e-16 against the column-by-column product (1e-12 allowed). Factorisations measured: 2 against 4 (the
reference's eigensolver ran two passes for the cutoff). A wrong clamped row in the block right-hand sides (the
boundary value dropped) moves the static block by O(1); a factor that is not the clamped K's moves the frequencies
by O(1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CASES

MOTOR = CASES / "wwusm-motor.toml"
COARSE = ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
          "reduction.interface_nodes=32"]


def _factorisations() -> int:
    from petsc4py import PETSc

    return sum(int(PETSc.Log.Event(name).getPerfInfo()["count"]) for name in ("MatLUFactorNum",
                                                                               "MatCholFctrNum"))


@pytest.fixture(scope="module")
def bases():
    from mpi4py import MPI
    from petsc4py import PETSc

    from app.case.schema import load_case
    from app.contact.sites import contact_site_sets
    from app.fe.model import build_model
    from app.fe.operators import assemble_operators
    from app.reduced.craig_bampton import reduce_model

    PETSc.Log.begin()
    case = load_case(MOTOR, COARSE)
    model = build_model(case, MPI.COMM_WORLD)
    _, interface, _ = contact_site_sets(case, model)
    ops = assemble_operators(model, damping_frequency_Hz=36065.0)
    fixed = np.concatenate([model.support_dofs, model.grounded_dofs]
                           + [model.electrode_dofs[n] for n in model.electrodes_of("ground")])
    electrodes = {n: model.electrode_dofs[n] for n in model.electrodes_of("voltage")}
    out = {}
    for shared in (True, False):
        before = _factorisations()
        basis = reduce_model(ops.K, ops.M, ops.C, model.W, fixed, interface, electrodes,
                             cutoff_Hz=3 * 36065.0, n_enrich=2, enrich_near_Hz=36065.0, shared_factorisation=shared)
        out[shared] = (basis, _factorisations() - before)
    yield out, ops
    for basis, _ in out.values():
        basis.destroy()
    ops.destroy()


def _short_circuit_Hz(basis) -> np.ndarray:
    import scipy.linalg

    keep = np.setdiff1d(np.arange(basis.size), [basis.electrode_index(n) for n in basis.electrodes])
    lam = scipy.linalg.eigh(basis.K[np.ix_(keep, keep)], basis.M[np.ix_(keep, keep)], eigvals_only=True)
    return np.sqrt(np.abs(lam)) / (2 * math.pi)


@pytest.mark.mpi
def test_the_eigensolver_reuses_the_clamped_factorisation(bases):
    out, _ = bases
    assert out[True][1] == 2
    assert out[False][1] >= 3


@pytest.mark.mpi
def test_block_solves_and_shared_factor_give_the_reference_model(bases):
    from app.reduced.craig_bampton import harmonic_response

    out, _ = bases
    new, ref = out[True][0], out[False][0]
    assert new.size == ref.size and new.n_interface == ref.n_interface == 96
    np.testing.assert_allclose(new.mode_frequencies_Hz, ref.mode_frequencies_Hz, rtol=1e-10, atol=0)
    np.testing.assert_allclose(new.enrichment_frequencies_Hz, ref.enrichment_frequencies_Hz, rtol=1e-10, atol=0)
    np.testing.assert_allclose(_short_circuit_Hz(new), _short_circuit_Hz(ref), rtol=1e-10, atol=1e-6)
    static = new.n_interface + len(new.electrodes)
    for name in ("K", "M", "C"):
        a, b = getattr(new, name)[:static, :static], getattr(ref, name)[:static, :static]
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), name
    for name in new.electrodes:
        a, b = new.charge_rows[name][:static], ref.charge_rows[name][:static]
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), name
    # the drive: the four segments 90 deg apart, 0.1 % below the pair (a steep, near-resonant response)
    drive_Hz = 0.999 * float(np.mean(ref.enrichment_frequencies_Hz))
    voltages = {name: 200.0 * np.exp(1j * math.radians(90.0 * k)) for k, name in enumerate(new.electrodes)}
    q_new, q_ref = (harmonic_response(b, drive_Hz, voltages) for b in (new, ref))
    u_new, u_ref = q_new[:new.n_interface], q_ref[:ref.n_interface]
    assert np.abs(u_new - u_ref).max() <= 1e-8 * np.abs(u_ref).max()
    for name in new.electrodes:
        charge_new, charge_ref = new.charge_rows[name] @ q_new, ref.charge_rows[name] @ q_ref
        assert abs(charge_new - charge_ref) <= 1e-8 * abs(charge_ref)


@pytest.mark.mpi
def test_projection_is_the_column_by_column_product(bases):
    """_project's sparse-times-dense product against T^T (A t_j) column by column (the former implementation)."""
    from mpi4py import MPI

    from app.reduced.craig_bampton import _project

    out, ops = bases
    columns = out[True][0].columns
    lo, hi = ops.K.getOwnershipRange()
    rows = [np.arange(0, hi - lo, 7), np.zeros(0, dtype=np.int64)]     # local rows, and an empty set
    reduced = _project(ops.K, columns, MPI.COMM_WORLD)
    reduced_too, sums = _project(ops.K, columns, MPI.COMM_WORLD, summed_rows=rows)
    assert np.array_equal(reduced_too, reduced)
    y = ops.K.createVecLeft()
    reference = np.zeros_like(reduced)
    row_sums = np.zeros((len(rows), len(columns)))
    for j, column in enumerate(columns):
        ops.K.mult(column, y)
        reference[:, j] = [c.dot(y) for c in columns]
        row_sums[:, j] = [y.array_r[r].sum() for r in rows]
    y.destroy()
    reference = 0.5 * (reference + reference.T)
    assert np.abs(reduced - reference).max() <= 1e-12 * np.abs(reference).max()
    # the summed rows of K T (the charge rows), taken while PETSc's product exists
    scale = np.abs(row_sums).max()
    for i in range(len(rows)):
        assert np.abs(sums[i] - row_sums[i]).max() <= 1e-12 * scale
