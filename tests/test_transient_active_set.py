"""Newton on the active set (app/transient/active_set.py) against the all-DOF Newton of the condensed step.

The motor in the FE tier on a very coarse stator (P1, 4 mm / 2 mm elements, the seating test's model): the rotor
starts resting on the highest crest of the harmonic start (a touch-down), loaded by a torque, and the
travelling wave's crests carry the contact round the band, so facets close and open in every step and inside
Newton iterations. The same run with ``active_set=False`` solves the dense system on all s contact DOFs and
evaluates every FE DOF at every iterate (the step before this change). Reference: that run. Tolerance: each step's
Newton iteration stops at 1e-10 of its force scale (coupled.py), so two runs that differ in round-off (another
LU order, the restricted products) agree to ~1e-10 per step; over 80 steps 1e-7 of each series' largest value
leaves room for that and fails on any error in the eliminated rows (a missing update of an opened DOF moves the
rotor by ~1e-3 of its motion, seen by breaking it).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
from conftest import PINNED_MOTOR
from mpi4py import MPI

import app.transient.driver as driver
from app.case.schema import load_case
from app.transient.active_set import CondensedJacobian, ContactTangent
from app.transient.control import StepController, StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.stepper import TimeStepper

TINY_FE = ['tier="fe"', "geometry.degree=1", "geometry.parameters.mesh_size_m=0.004",
           "geometry.parameters.tip_mesh_size_m=0.002", "output.fields=false", "output.plots=false",
           "transient.bodies[0].rotations[0].torque_N_m=-0.005"]
STEPS = 80      # two drive periods


def quiet(*args):
    pass


def _run(system, state, steps):
    comm = MPI.COMM_WORLD
    stepper = TimeStepper(system, StepController(steps))
    records = []
    final = stepper.run(state, STEPS * steps.closed_s, on_step=records.append)
    counts = {"active_dofs": system.active_dofs, "jacobians": system.jacobians, "s": system.contact_global.size,
              "changes": comm.allreduce(system.active_set_changes), "opened": comm.allreduce(system.opened_updates),
              "cutbacks": stepper.stats.cutbacks}
    return records, final, counts


@pytest.fixture(scope="module")
def runs():
    """The same model and start, stepped by the active-set Newton (the driver's system) and by the all-DOF
    Newton (a second CoupledSystem on the same FE model, bodies and interactions)."""
    comm = MPI.COMM_WORLD
    case = load_case(PINNED_MOTOR, TINY_FE)
    tm = driver.build(case, comm, quiet)
    state, _ = tm.initial_state()
    s = case.transient.steps
    steps = StepSizes(s.open_s, s.closed_s, s.change_s, s.min_s)
    assert tm.system.active_set
    active = _run(tm.system, state, steps)
    reference = CoupledSystem(comm, case.transient.scheme.scheme(), tm.fe, tm.rigid, tm.system.interactions,
                              active_set=False)
    result = active, _run(reference, state, steps)
    tm.system.destroy()
    reference.destroy()
    return result


@pytest.mark.mpi
def test_active_set_newton_equals_the_all_dof_newton(runs):
    (records, final, counts), (ref_records, ref_final, ref_counts) = runs
    assert counts["cutbacks"] == ref_counts["cutbacks"] == 0
    assert len(records) == len(ref_records) == STEPS
    np.testing.assert_allclose([r["time_s"] for r in records], [r["time_s"] for r in ref_records], rtol=1e-12)
    for key in ("position_m", "velocity_m_per_s"):
        a = np.array([r[key] for r in records])
        b = np.array([r[key] for r in ref_records])
        moved = a - a[0]
        scale = np.max(np.abs(b - b[0]), axis=0)
        assert np.all(scale[[2, 3]] > 0)                       # the rotor moves axially and spins
        np.testing.assert_allclose(moved, b - b[0], rtol=0, atol=1e-7 * np.max(scale))
    force = np.array([r["contact_force_N"]["stator_rotor"] for r in records])
    ref_force = np.array([r["contact_force_N"]["stator_rotor"] for r in ref_records])
    assert np.max(np.abs(ref_force[:, 2])) > 0.2                # landing under the 0.98 N preload
    np.testing.assert_allclose(force, ref_force, rtol=0, atol=1e-7 * np.max(np.abs(ref_force)))
    assert np.max(np.abs(final.u - ref_final.u)) <= 1e-7 * np.max(np.abs(ref_final.u))


@pytest.mark.mpi
def test_the_active_set_changes_inside_newton_iterations(runs):
    """The comparison above covers what it has to: contact DOFs joined or left the active set between two
    Newton iterations of one step, and updates took DOFs carrying force off it (their force set to zero by
    the eliminated rows); the reference solved every Jacobian on all s DOFs."""
    (_, _, counts), (_, _, ref_counts) = runs
    print(counts, ref_counts)
    if MPI.COMM_WORLD.rank == 0:
        assert counts["changes"] >= 3
        assert counts["opened"] >= 3
        assert counts["active_dofs"] < 0.5 * counts["s"] * counts["jacobians"]     # most DOFs are open
        assert ref_counts["active_dofs"] == ref_counts["s"] * ref_counts["jacobians"]


@pytest.mark.parametrize("s_count", [40, 200])        # all-DOF dense, and eliminated (active_set.DENSE_MAX)
def test_the_eliminated_system_solves_and_applies_the_full_newton_matrix(s_count):
    """CondensedJacobian against the dense J = [[-(I + Kss G), B], [-L G, Kzz]] on all s DOFs: J^-1 x and J x
    for x with nonzero entries at open DOFs (forces of DOFs that have opened). Reference: numpy's dense solve;
    tolerance 1e-10 relative: both are backward stable on a matrix of condition ~1e3."""
    rng = np.random.default_rng(7)
    m = 4
    root = rng.normal(size=(s_count, s_count))
    G = root @ root.T / s_count + np.eye(s_count)                          # G = E^T K_eff^-1 E: SPD
    closed = np.zeros(s_count, dtype=bool)
    closed[rng.choice(s_count, s_count // 3, replace=False)] = True
    mask = np.outer(closed, closed) & (rng.random((s_count, s_count)) < 0.1)
    Kss = np.where(mask, rng.normal(size=(s_count, s_count)), 0.0) + np.diag(np.where(closed, 5.0, 0.0))
    B = np.where(closed[:, None], rng.normal(size=(s_count, m)), 0.0)
    L = np.where(closed[None, :], rng.normal(size=(m, s_count)), 0.0)
    Kzz = rng.normal(size=(m, m)) + 5 * np.eye(m)
    J = np.block([[-(np.eye(s_count) + Kss @ G), B], [-L @ G, Kzz]])
    tangent = ContactTangent(s_count)
    tangent += scipy.sparse.csr_matrix(Kss)
    assert tangent.dense == (s_count <= 64)
    jacobian = CondensedJacobian(G, tangent, B, L, Kzz)
    assert jacobian.active_count == (closed.sum() if s_count > 64 else s_count)
    for _ in range(3):
        x = rng.normal(size=s_count + m)                                   # nonzero at open DOFs too
        np.testing.assert_allclose(jacobian.solve(x), np.linalg.solve(J, x), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(jacobian.apply(x), J @ x, rtol=1e-10, atol=1e-12)
    reference = CondensedJacobian(G, Kss, B, L, Kzz, active_only=False)
    assert reference.active_count == s_count
    np.testing.assert_allclose(reference.solve(x), np.linalg.solve(J, x), rtol=1e-10, atol=1e-12)
