"""Saint-Venant rod impact on a rigid wall: duration 2L/c and force rho c A v0, energy closure,
stiff-penalty robustness and MPI = serial."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from app.transient.stepper import run_scene
from demos.demo_rod_impact import RodImpact, build_rod_impact, contact_pulse, rod_step_sizes
from forms.newmark import TimeScheme


def run_rod(rod: RodImpact, comm=MPI.COMM_WORLD, scheme=None, **kwargs):
    system, state = build_rod_impact(comm, rod, scheme or TimeScheme.newmark())
    records, final, stepper = run_scene(system, state, rod_step_sizes(rod), 1.4 * rod.contact_duration_s,
                                        **kwargs)
    return records, final, stepper


def test_rod_impact_matches_saint_venant():
    """Generalized-alpha (rho_inf = 0.5) removes the step-to-step chatter of the contact node, so
    the force plateau itself is checked tightly (1 %: measured 2e-6 at 40 elements). At 40 elements
    the dispersed wave front makes the pulse 1.6 % long and its impulse 1.1 % short (see the
    convergence test below), so the duration gets 3 % and the impulse-mean force (2.6 % low) 5 %."""
    rod = RodImpact(elements_along=40)
    records, _, stepper = run_rod(rod, scheme=TimeScheme.generalized_alpha(0.5))
    duration, mean_force, median_force, peak = contact_pulse(records)
    assert duration == pytest.approx(rod.contact_duration_s, rel=0.03)
    assert mean_force == pytest.approx(rod.contact_force_N, rel=0.05)
    assert median_force == pytest.approx(rod.contact_force_N, rel=0.01)
    assert peak < 2.0 * rod.contact_force_N     # the wave-front overshoot of a penalty contact
    # The rod leaves with its speed reversed (elastic impact), still ringing in its breathing mode.
    v_end = records[-1]
    assert stepper.stats.cutbacks == 0
    assert v_end["contact_closed"].tolist() == [0]


def test_rod_impact_energy_balance_closes():
    rod = RodImpact(elements_along=40)
    records, _, _ = run_rod(rod, track_energy=True)
    e0 = 0.5 * rod.density_kg_per_m3 * rod.length_m * rod.height_m * rod.speed_m_per_s**2
    totals = np.array([r["energy_J"]["total_J"] for r in records])
    # Undamped, no loads: the trapezoidal rule conserves energy except through the penalty's kink.
    assert np.max(np.abs(totals - e0)) / e0 < 0.01
    peak_contact = max(r["energy_J"]["contact_J"] for r in records)
    assert peak_contact > 1e-4 * e0


def test_rod_impact_with_1000x_penalty_finishes():
    rod = RodImpact(elements_along=20, penalty_factor=10.0 * 1000)
    records, _, stepper = run_rod(rod, scheme=TimeScheme.generalized_alpha(0.5))
    duration, mean_force, _, _ = contact_pulse(records)
    # 1000x the penalty on 20 elements: the end node rattles and the pulse ends ~6 % early;
    # the point here is that the run finishes and the impulse stays right.
    assert duration == pytest.approx(rod.contact_duration_s, rel=0.10)
    assert mean_force == pytest.approx(rod.contact_force_N, rel=0.10)
    assert stepper.stats.steps > 0


def test_rod_impact_trapezoidal_rule_pulse():
    """The non-dissipative rule gets duration and impulse right, but the contact node chatters
    (peaks ~2x the plateau): that is what the dissipative option is for."""
    rod = RodImpact(elements_along=40)
    records, _, _ = run_rod(rod, scheme=TimeScheme.newmark())
    duration, mean_force, median_force, peak = contact_pulse(records)
    assert duration == pytest.approx(rod.contact_duration_s, rel=0.03)
    assert mean_force == pytest.approx(rod.contact_force_N, rel=0.05)
    assert median_force == pytest.approx(rod.contact_force_N, rel=0.05)


def _pulse_errors(elements: tuple[int, ...]):
    """Per mesh: (relative error of the contact duration against 2L/c, of the wall's impulse against
    the momentum 2 m v0 of an elastic rebound, of the median force against rho c A v0)."""
    duration_err, impulse_err, force_err = [], [], []
    for n in elements:
        rod = RodImpact(elements_along=n)
        records, _, _ = run_rod(rod, scheme=TimeScheme.generalized_alpha(0.5))
        duration, mean_force, median_force, _ = contact_pulse(records)
        momentum = rod.density_kg_per_m3 * rod.length_m * rod.height_m * rod.speed_m_per_s
        duration_err.append(abs(duration / rod.contact_duration_s - 1))
        impulse_err.append(abs(mean_force * duration / (2 * momentum) - 1))
        force_err.append(abs(median_force / rod.contact_force_N - 1))
    return np.array(duration_err), np.array(impulse_err), np.array(force_err)


# Penalty contact under mesh refinement (dt = the element transit time, the penalty 10x an element's
# axial stiffness, so both refine with h). The pulse is a step wave: a second-order scheme's
# dispersion spreads its front like an Airy function over (h^2 L)^(1/3), so the contact's end (the
# returning front) and the impulse it lets through converge like h^(2/3), not h: measured orders 0.60
# (10-80 elements), 0.65 (20-160), 0.68 (40-320) for the duration; 0.49, 0.55, 0.59 for the impulse.
# The force plateau is resolved exactly once the front is a few elements wide (1e-6 at 40 elements).
AIRY_ORDER = 2.0 / 3.0


@pytest.mark.mpi
def test_rod_impact_converges_under_refinement():
    """Coarse (CI): 10, 20, 40, 80 elements, pre-asymptotic: the duration's observed order within
    0.15 of 2/3, the impulse's above 0.4, all errors falling, the plateau to 0.2 % from 20 elements."""
    from ieee176 import observed_order

    elements = (10, 20, 40, 80)
    duration, impulse, force = _pulse_errors(elements)
    h = [1.0 / n for n in elements]
    assert np.all(np.diff(duration) < 0) and np.all(np.diff(impulse) < 0)
    assert abs(observed_order(h, duration) - AIRY_ORDER) < 0.15, duration
    assert observed_order(h, impulse) > 0.4, impulse
    assert np.all(force[1:] < 2e-3), force
    assert duration[-1] < 0.015 and impulse[-1] < 0.01


@pytest.mark.slow
def test_rod_impact_converges_under_refinement_fine():
    """Fine: 40 to 320 elements, near the asymptote: the duration's order within 0.05 of 2/3, the
    impulse's above 0.5, the duration to 0.4 % and the impulse to 0.35 % at 320 elements."""
    from ieee176 import observed_order

    elements = (40, 80, 160, 320)
    duration, impulse, force = _pulse_errors(elements)
    h = [1.0 / n for n in elements]
    assert np.all(np.diff(duration) < 0) and np.all(np.diff(impulse) < 0)
    assert abs(observed_order(h, duration) - AIRY_ORDER) < 0.05, duration
    assert observed_order(h, impulse) > 0.5, impulse
    assert np.all(force < 1e-5), force
    assert duration[-1] < 0.004 and impulse[-1] < 0.0035


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="compares a parallel run with a serial one")
def test_rod_impact_parallel_equals_serial():
    rod = RodImpact(elements_along=40)
    parallel, _, _ = run_rod(rod, comm=MPI.COMM_WORLD)
    serial, _, _ = run_rod(rod, comm=MPI.COMM_SELF)
    assert len(parallel) == len(serial)
    t_p = np.array([r["time_s"] for r in parallel])
    t_s = np.array([r["time_s"] for r in serial])
    np.testing.assert_allclose(t_p, t_s, rtol=1e-12)
    f_p = np.array([r["contact_force_N"]["rod_wall"][0] for r in parallel])
    f_s = np.array([r["contact_force_N"]["rod_wall"][0] for r in serial])
    np.testing.assert_allclose(f_p, f_s, rtol=1e-7, atol=1e-7 * rod.contact_force_N)


def test_effective_operator_lu_matches_mumps():
    """The serial K_eff factorisation (PETSc's LU, checked by its backward error) solves like MUMPS;
    a failed check (threshold below any achievable error) falls back to MUMPS."""
    from app.transient.fe import EffectiveOperator

    rod = RodImpact(elements_along=20)
    system, _ = build_rod_impact(MPI.COMM_WORLD, rod, TimeScheme.generalized_alpha(0.5))
    op = system.cache.get(rod_step_sizes(rod).closed_s)
    assert op.solver_type == ("petsc" if MPI.COMM_WORLD.size == 1 else "mumps")
    assert op._backward_error() < 1e-13
    mumps = EffectiveOperator._factorise(MPI.COMM_WORLD, op.constrained, "mumps")
    rhs = op.constrained.createVecRight()
    lo, hi = rhs.getOwnershipRange()
    rhs.array_w[:] = np.cos(np.arange(lo, hi) * 0.37)
    x, y = rhs.duplicate(), rhs.duplicate()
    op.solve(rhs, x)
    mumps.solve(rhs, y)
    y.axpy(-1.0, x)
    assert y.norm() < 1e-10 * x.norm()
    import app.transient.fe as fe_module

    original = fe_module.EffectiveOperator._backward_error
    fe_module.EffectiveOperator._backward_error = lambda self: 1.0
    try:
        fallback = EffectiveOperator(system.fe, op.dt, system.scheme, system.contact_global)
    finally:
        fe_module.EffectiveOperator._backward_error = original
    assert fallback.solver_type == "mumps"
    fallback.destroy()
    mumps.destroy()
    system.destroy()
