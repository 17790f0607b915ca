"""The viscous brake on a free rotation (app/transient/rigid.py, brake_N_m_s_per_rad): a rotor of
inertia J under a constant torque T against a brake c spins up as Omega (1 - exp(-c t / J)) towards
Omega = T / c, and a rotor set spinning with no torque decays as omega_0 exp(-c t / J). The brake
is a load at the step's generalised mid-point with its exact tangent, so the (linear) rigid step
converges in one Newton iteration, and with average-acceleration Newmark the work of torque and
brake equals the change of kinetic energy to round-off."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from app.transient.control import StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.rigid import RigidBody, RigidSet
from app.transient.stepper import run_scene
from forms.newmark import TimeScheme

INERTIA_KG_M2, BRAKE_N_M_S, TORQUE_N_M = 2e-6, 1e-5, 3e-3
TAU_S = INERTIA_KG_M2 / BRAKE_N_M_S                   # 0.2 s


def spin(torque_N_m: float, omega0: float, scheme: TimeScheme, steps_per_tau: int = 200, taus: float = 5.0):
    rotor = RigidBody("rotor", 0.01, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                      prescribed_axes=(True, True, True, False), rotation_axes=("z",),
                      inertia_kg_m2=(INERTIA_KG_M2,), angular_velocity_rad_per_s=(omega0,),
                      applied_torque_N_m=lambda t: np.array([torque_N_m]), brake_N_m_s_per_rad=(BRAKE_N_M_S,))
    system = CoupledSystem(MPI.COMM_WORLD, scheme, None, RigidSet([rotor]))
    z, zd, zdd = system.rigid.initial_state()
    from app.transient.state import TransientState

    empty = np.zeros(0)
    state = system.consistent_rigid_acceleration(TransientState(0.0, empty, empty, empty, z, zd, zdd))
    dt = TAU_S / steps_per_tau
    records, final, stepper = run_scene(system, state, StepSizes(dt, dt, dt, 1e-12), taus * TAU_S, track_energy=True)
    t = np.array([r["time_s"] for r in records])
    omega = np.array([r["velocity_m_per_s"][3] for r in records])
    return t, omega, stepper


@pytest.mark.parametrize("scheme", [TimeScheme.newmark(0.25, 0.5), TimeScheme.generalized_alpha(0.5)],
                         ids=["newmark", "generalized_alpha"])
def test_braked_rotor_under_constant_torque_reaches_torque_over_brake(scheme):
    t, omega, stepper = spin(TORQUE_N_M, 0.0, scheme)
    terminal = TORQUE_N_M / BRAKE_N_M_S                                    # 300 rad/s
    exact = terminal * (1 - np.exp(-t / TAU_S))
    # second-order schemes at 200 steps per time constant: ~1e-5 of the terminal speed
    assert np.max(np.abs(omega - exact)) < 1e-4 * terminal
    assert omega[-1] == pytest.approx(terminal * (1 - math.exp(-5.0)), rel=1e-5)
    # the brake's tangent is exact: one Newton iteration per (linear) step
    assert stepper.stats.cutbacks == 0 and stepper.system.total_iterations == stepper.stats.steps


def test_braked_rotor_spins_down_exponentially_and_its_energy_balances():
    omega0 = 500.0
    t, omega, stepper = spin(0.0, omega0, TimeScheme.newmark(0.25, 0.5), taus=3.0)
    np.testing.assert_allclose(omega, omega0 * np.exp(-t / TAU_S), rtol=1e-5)
    energy = stepper.energy
    final = energy.energy_J(stepper.system._new_state())
    # trapezoidal work of the brake torque over Newmark's angle increments = change of 1/2 J omega^2
    assert final["total_J"] - energy.initial["total_J"] == pytest.approx(energy.work_J, rel=1e-10)
    assert energy.work_J == pytest.approx(-0.5 * INERTIA_KG_M2 * omega0**2 * (1 - math.exp(-6.0)), rel=1e-4)
