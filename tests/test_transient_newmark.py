"""Newmark / generalized-alpha: spectral properties, energy conservation over 1e4 steps, and
high-frequency-only damping on an elastic rod."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI

from app.transient.control import StepController, StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.fe import LinearFE
from app.transient.rigid import RigidSet
from app.transient.state import TransientState
from app.transient.stepper import EnergyAccount, TimeStepper
from forms.dynamics import mass
from forms.newmark import TimeScheme, spectral_radius
from forms.piezo import elastic_stiffness
from forms.voigt import isotropic_stiffness


@pytest.mark.parametrize("rho_inf", [0.0, 0.3, 0.8])
def test_generalized_alpha_spectral_radius_limits(rho_inf):
    scheme = TimeScheme.generalized_alpha(rho_inf)
    assert scheme.is_second_order
    assert spectral_radius(1e8, scheme) == pytest.approx(rho_inf, abs=1e-3)
    # Low frequencies (40 steps per period) keep their amplitude to 1.5 % per period even for
    # the most dissipative setting (0.11 % at rho_inf = 0.8).
    rho_low = spectral_radius(2 * math.pi / 40, scheme)
    assert 1 - rho_low**40 < 1.5e-2 * (1 - rho_inf) + 1e-3


def test_trapezoidal_rule_is_non_dissipative_at_every_frequency():
    scheme = TimeScheme.newmark()
    for omega_dt in (1e-3, 0.1, 1.0, 10.0, 1e4):
        assert spectral_radius(omega_dt, scheme) == pytest.approx(1.0, abs=1e-12)


def test_hht_limits():
    assert spectral_radius(1e7, TimeScheme.hht(-0.3)) == pytest.approx((1 - 0.3) / (1 + 0.3), abs=1e-3)
    with pytest.raises(ValueError):
        TimeScheme.hht(-0.5)


def _clamped_rod(comm, elements=12, degree=1):
    length, height = 0.1, 0.01
    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([length, height])], [elements, 1],
                                cell_type=mesh.CellType.quadrilateral, ghost_mode=mesh.GhostMode.shared_facet)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", degree))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.dx(domain=msh)
    c = fem.Constant(msh, isotropic_stiffness(200e9, 0.25))
    rho = fem.Constant(msh, 7850.0)
    fdim = msh.topology.dim - 1
    clamped = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 0.0))
    bc = fem.dirichletbc(np.zeros(2), fem.locate_dofs_topological(V, fdim, clamped), V)
    fe = LinearFE(V, V, mass(u, w, rho, dx), elastic_stiffness(u, w, c, "plane_strain", dx), bcs=[bc])
    return V, fe


def _state(V, u0=None, v0=None, a0=None):
    n = fem.Function(V).x.array.size
    zero = np.zeros(n)
    return TransientState(0.0, zero if u0 is None else u0, zero if v0 is None else v0,
                          zero if a0 is None else a0, np.zeros(0), np.zeros(0), np.zeros(0))


def test_average_acceleration_conserves_energy_over_10000_steps():
    comm = MPI.COMM_WORLD
    V, fe = _clamped_rod(comm, elements=6)
    system = CoupledSystem(comm, TimeScheme.newmark(), fe, RigidSet([]))
    velocity = fem.Function(V)
    velocity.interpolate(lambda x: np.vstack([np.sin(40 * x[0]) + 3 * x[0] * x[1] * 1e3, np.cos(30 * x[0])]))
    velocity.x.array[fe.bc_local_owned] = 0.0
    velocity.x.scatter_forward()
    state = _state(V, v0=velocity.x.array.copy())
    account = EnergyAccount(system)
    e0 = account.energy_J(state)["total_J"]
    dt = 2e-7
    sizes = StepSizes(open_s=dt, closed_s=dt, change_s=dt, min_s=dt / 1024)
    energies = []
    stepper = TimeStepper(system, StepController(sizes))
    final = stepper.run(state, 10_000 * dt, on_step=lambda rec: None)
    assert stepper.stats.steps >= 10_000
    assert stepper.stats.cutbacks == 0
    energies.append(account.energy_J(final)["total_J"])
    # Strain energy must really have been exchanged (the test would be empty otherwise).
    assert account.energy_J(final)["strain_fe_J"] > 1e-3 * e0
    assert abs(energies[-1] - e0) / e0 < 1e-9
    assert stepper.stats.factorisations == 1


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="dense modal analysis in serial")
def test_generalized_alpha_damps_only_the_high_mode():
    comm = MPI.COMM_SELF
    V, fe = _clamped_rod(comm, elements=12)
    K = fe.K.copy().convert("dense").getDenseArray()
    M = fe.M.copy().convert("dense").getDenseArray()
    free = np.setdiff1d(np.arange(K.shape[0]), fe.bc_local_owned)
    w2, modes = scipy.linalg.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)])
    omega = np.sqrt(w2)
    low, high = 0, len(omega) - 1
    period_low = 2 * math.pi / omega[low]
    dt = period_low / 40
    assert omega[high] * dt > 30        # the high mode is far beyond the resolved band

    def run(scheme):
        phi = np.zeros((K.shape[0], 2))
        phi[free, 0], phi[free, 1] = modes[:, low], modes[:, high]
        u0 = phi[:, 0] + phi[:, 1]
        a0 = -(phi[:, 0] * omega[low] ** 2 + phi[:, 1] * omega[high] ** 2)
        system = CoupledSystem(comm, scheme, fe, RigidSet([]))
        sizes = StepSizes(open_s=dt, closed_s=dt, change_s=dt, min_s=dt / 64)
        final = TimeStepper(system, StepController(sizes)).run(_state(V, u0=u0, a0=a0), 2 * period_low)
        q = phi.T @ M @ final.u
        qd = phi.T @ M @ final.v
        energy = 0.5 * (qd**2 + np.array([omega[low], omega[high]]) ** 2 * q**2)
        return energy / (0.5 * np.array([omega[low], omega[high]]) ** 2)

    trapezoidal = run(TimeScheme.newmark())
    assert trapezoidal == pytest.approx([1.0, 1.0], rel=1e-8)
    dissipative = run(TimeScheme.generalized_alpha(0.5))
    assert dissipative[0] == pytest.approx(1.0, rel=5e-3)       # resolved mode kept
    assert dissipative[1] < 1e-6                                # unresolved mode removed


@pytest.mark.parametrize("scheme", [TimeScheme.newmark(), TimeScheme.generalized_alpha(0.5), TimeScheme.hht(-0.1)])
def test_fused_kinematics_are_the_newmark_expressions_bit_for_bit(scheme):
    """The condensed step's one-pass kernels (app/transient/kinematics.py) against forms/newmark.py's
    acceleration, velocity and midpoint applied to arrays, and the predictor residual's mat-vec arguments against
    their numpy formulas (app/transient/coupled.py before the kernels). Reference: those expressions; tolerance 0
    (bit for bit): the kernels evaluate the same operations in the same order without fused multiply-adds, so any
    difference is a changed formula (a sign, a factor, an alpha_f for a gamma)."""
    from app.transient.kinematics import (
        increment_kinematics,
        predictor_arguments,
        scheme_factors,
        step_kinematics,
        step_kinematics_at,
        step_rates,
        taylor_predictor,
    )
    from forms.newmark import acceleration, midpoint, velocity

    rng = np.random.default_rng(7)
    dt = 2.5e-7
    n = 1001
    u1, u0, v0, a0 = (rng.standard_normal(n) * scale for scale in (1e-6, 1e-6, 1e-1, 1e5))
    factors = scheme_factors(dt, scheme)
    a1 = acceleration(u1, u0, v0, a0, dt, scheme)
    v1 = velocity(a1, v0, a0, dt, scheme)
    expected = (a1, v1, midpoint(u1, u0, scheme.alpha_f), midpoint(v1, v0, scheme.alpha_f))
    fused = np.empty((4, n))
    step_kinematics(u1, u0, v0, a0, factors, *fused)
    for got, want in zip(fused, expected):
        np.testing.assert_array_equal(got, want)
    rates = np.empty((2, n))
    step_rates(u1, u0, v0, a0, factors, *rates)
    np.testing.assert_array_equal(rates[0], expected[0])
    np.testing.assert_array_equal(rates[1], expected[1])
    at = np.array([3, 17, 500, 1000])
    out = np.zeros((4, n))
    step_kinematics_at(at, u1, u0, v0, a0, factors, *out)
    for got, want in zip(out, expected):
        np.testing.assert_array_equal(got[at], want[at])
        assert not got[np.setdiff1d(np.arange(n), at)].any()
    # rigid coordinates: the acceleration from the increment, the mid-point position from the positions
    dz = u1 - u0
    out = np.empty((4, n))
    increment_kinematics(dz, u1, u0, v0, a0, factors, *out)
    a1 = acceleration(dz, 0.0, v0, a0, dt, scheme)
    v1 = velocity(a1, v0, a0, dt, scheme)
    for got, want in zip(out, (a1, v1, midpoint(u1, u0, scheme.alpha_f), midpoint(v1, v0, scheme.alpha_f))):
        np.testing.assert_array_equal(got, want)
    # the predictor u_n + dt v_n + dt^2/2 a_n and the M, K, C arguments with a Dirichlet change on a few DOFs
    pred = np.empty(n)
    bc = np.array([0, 5, 9], dtype=np.int32)
    taylor_bc = np.empty(bc.size)
    taylor_predictor(u0, v0, a0, dt, pred, bc, taylor_bc)
    want = v0 * dt
    want += u0
    want += (0.5 * dt * dt) * a0
    np.testing.assert_array_equal(pred, want)
    np.testing.assert_array_equal(taylor_bc, want[bc])
    pred[bc] += 1e-9 * rng.standard_normal(bc.size)        # the Dirichlet change
    delta_bc = pred[bc] - taylor_bc
    mass_factor, damping_factor = 3.7e12, 2.1e6
    one_minus_af = 1 - scheme.alpha_f
    args = np.empty((3, n))
    predictor_arguments(pred, u0, v0, a0, dt, bc, taylor_bc, mass_factor, damping_factor, one_minus_af, *args)
    mass_arg = a0.copy()
    mass_arg[bc] += mass_factor * delta_bc
    damping_arg = a0 * dt
    damping_arg[bc] += damping_factor * delta_bc
    np.testing.assert_array_equal(args[0], mass_arg)
    np.testing.assert_array_equal(args[1], (pred - u0) * one_minus_af + u0)
    np.testing.assert_array_equal(args[2], damping_arg * one_minus_af + v0)
