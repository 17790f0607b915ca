"""Interactions with friction and rotating rigid bodies (app/transient/interactions.py, rigid.py,
contact.py) against closed forms:

- a disc spinning on a plane with kinetic friction, its axle held: omega falls linearly at
  mu_d N R / J until it stops;
- the same disc free to roll: omega falls and the centre speeds up linearly until rolling starts,
  and the angular momentum about the contact line J omega - m R v is conserved throughout, so
  the rolling state is omega = J omega_0 / (J + m R^2);
- a block on a belt moving at a prescribed speed: kinetic friction mu_d N while slipping, stick
  below mu_s N = FACT mu_d N, break-away above it, and the force cap respected.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from app.transient.contact import Friction, PointContact
from app.transient.control import StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.rigid import RigidBody, RigidSet, constant_rate_motion, fixed_body
from app.transient.state import TransientState
from app.transient.stepper import run_scene
from forms.newmark import TimeScheme

MASS_KG, RADIUS_M, NORMAL_N = 1.0, 0.05, 10.0
INERTIA_KG_M2 = 0.5 * MASS_KG * RADIUS_M**2
STIFFNESS_N_PER_M = 1e6
DAMPING_N_S_PER_M = 2 * math.sqrt(STIFFNESS_N_PER_M * MASS_KG)     # critical: no normal bounce
MU_D = 0.3
OMEGA0_RAD_PER_S = 100.0
SIZES = StepSizes(open_s=1e-3, closed_s=1e-3, change_s=1e-3, min_s=1e-9)


def _disc_on_plane(axle_held: bool, friction: Friction, gdim: int = 2):
    """A disc resting on a fixed plane at static equilibrium under NORMAL_N, spinning: in 2D about
    the out-of-plane axis (slip along +x at the contact), in 3D a wheel spinning about x on the
    plane z = 0 (slip along +y)."""
    up = np.eye(gdim)[-1]
    ground = fixed_body("ground", np.zeros(gdim))
    held = (axle_held,) * (gdim - 1) + (False, False)
    disc = RigidBody("disc", MASS_KG, (RADIUS_M - NORMAL_N / STIFFNESS_N_PER_M) * up, np.zeros(gdim),
                     np.zeros(gdim), applied_force_N=lambda t: -NORMAL_N * up, prescribed_axes=held,
                     rotation_axes=("plane",) if gdim == 2 else ("x",), inertia_kg_m2=(INERTIA_KG_M2,),
                     angular_velocity_rad_per_s=(OMEGA0_RAD_PER_S,))
    rigid = RigidSet([ground, disc])
    link = PointContact("disc_ground", "ground", "disc", up, RADIUS_M, STIFFNESS_N_PER_M,
                        DAMPING_N_S_PER_M, friction=friction, contact_offset_m=RADIUS_M)
    system = CoupledSystem(MPI.COMM_WORLD, TimeScheme.generalized_alpha(0.5), None, rigid, [link])
    z, zd, zdd = rigid.initial_state()
    empty = np.zeros(0)
    state = system.consistent_rigid_acceleration(TransientState(0.0, empty, empty, empty, z, zd, zdd))
    return system, state


def _omega(records, system):
    rot = system.rigid.rotation_dofs("disc")
    return (np.array([r["time_s"] for r in records]),
            np.array([r["velocity_m_per_s"][rot][0] for r in records]))


@pytest.mark.parametrize("gdim", [2, 3])
def test_spinning_disc_with_held_axle_spins_down_linearly(gdim):
    friction = Friction(MU_D, regularisation_speed_m_per_s=1e-5)
    system, state = _disc_on_plane(True, friction, gdim)
    records, _, _ = run_scene(system, state, SIZES, 0.8)
    t, omega = _omega(records, system)
    deceleration = MU_D * NORMAL_N * RADIUS_M / INERTIA_KG_M2            # 120 rad/s^2
    t_stop = OMEGA0_RAD_PER_S / deceleration
    slipping = t < t_stop - 0.05                                          # slip speed > 0.3 m/s
    exact = OMEGA0_RAD_PER_S - deceleration * t[slipping]
    assert slipping.sum() > 700
    assert np.max(np.abs(omega[slipping] - exact) / exact) < 1e-6
    # the friction force is mu_d N against the slip (the contact point moves along +x, 3D: +y)
    force = np.array([r["contact_force_N"]["disc_ground"] for r in records])[slipping]
    np.testing.assert_allclose(force[:, gdim - 2], -MU_D * NORMAL_N, rtol=1e-6)
    np.testing.assert_allclose(force[:, -1], NORMAL_N, rtol=1e-9)
    if gdim == 3:
        np.testing.assert_allclose(force[:, 0], 0.0, atol=1e-12)


@pytest.mark.mpi
def test_spinning_disc_free_to_roll_conserves_contact_angular_momentum():
    friction = Friction(MU_D, regularisation_speed_m_per_s=1e-5)
    system, state = _disc_on_plane(False, friction)
    records, final, _ = run_scene(system, state, SIZES, 0.8)
    t, omega = _omega(records, system)
    v = np.array([r["velocity_m_per_s"][system.rigid.dofs("disc")][0] for r in records])
    # slipping: omega' = -mu N R / J, v' = -mu N / m until v + omega R = 0
    deceleration = MU_D * NORMAL_N * RADIUS_M / INERTIA_KG_M2
    acceleration = MU_D * NORMAL_N / MASS_KG
    t_roll = OMEGA0_RAD_PER_S * RADIUS_M / (acceleration + deceleration * RADIUS_M)
    slipping = t < t_roll - 0.05
    np.testing.assert_allclose(omega[slipping], OMEGA0_RAD_PER_S - deceleration * t[slipping], rtol=1e-6)
    np.testing.assert_allclose(v[slipping], -acceleration * t[slipping], rtol=1e-6)
    # friction acts at the contact line: J omega - m R v is J omega_0 at every step
    momentum = INERTIA_KG_M2 * omega - MASS_KG * RADIUS_M * v
    np.testing.assert_allclose(momentum, INERTIA_KG_M2 * OMEGA0_RAD_PER_S, rtol=1e-9)
    # rolling after t_roll: v = -omega R at omega = J omega_0 / (J + m R^2)
    rolling = t > t_roll + 0.05
    omega_roll = INERTIA_KG_M2 * OMEGA0_RAD_PER_S / (INERTIA_KG_M2 + MASS_KG * RADIUS_M**2)
    np.testing.assert_allclose(omega[rolling], omega_roll, rtol=1e-6)
    np.testing.assert_allclose(v[rolling], -omega_roll * RADIUS_M, rtol=1e-6)


# ---------------------------------------------------------------- block on a belt
BELT_M_PER_S = 1.0
BLOCK_KG = 0.5
FACT, DECAY_S_PER_M = 1.5, 100.0      # mu_s = 0.45; mu within 1e-8 of mu_d above 0.2 m/s of slip


def _block_on_belt(friction: Friction, push_N: float, block_speed_m_per_s: float):
    belt = RigidBody("belt", 0.0, [0.0, 0.0], [BELT_M_PER_S, 0.0], [0.0, 0.0], prescribed_axes=(True, True),
                     prescribed=constant_rate_motion([0.0, 0.0], [BELT_M_PER_S, 0.0]))
    block = RigidBody("block", BLOCK_KG, [0.0, -NORMAL_N / STIFFNESS_N_PER_M], [block_speed_m_per_s, 0.0],
                      [0.0, 0.0], applied_force_N=lambda t: np.array([push_N, -NORMAL_N]))
    rigid = RigidSet([belt, block])
    link = PointContact("block_belt", "belt", "block", [0.0, 1.0], 0.0, STIFFNESS_N_PER_M,
                        2 * math.sqrt(STIFFNESS_N_PER_M * BLOCK_KG), friction=friction)
    system = CoupledSystem(MPI.COMM_WORLD, TimeScheme.generalized_alpha(0.5), None, rigid, [link])
    z, zd, zdd = rigid.initial_state()
    empty = np.zeros(0)
    state = system.consistent_rigid_acceleration(TransientState(0.0, empty, empty, empty, z, zd, zdd))
    records, _, _ = run_scene(system, state, SIZES, 0.3)
    t = np.array([r["time_s"] for r in records])
    v = np.array([r["velocity_m_per_s"][rigid.dofs("block")][0] for r in records])
    friction_N = np.array([r["contact_force_N"]["block_belt"][0] for r in records])
    return t, v, friction_N


def test_block_on_belt_slips_at_kinetic_friction_then_sticks():
    friction = Friction(MU_D, FACT, DECAY_S_PER_M, regularisation_speed_m_per_s=1e-5)
    t, v, force = _block_on_belt(friction, 0.0, 0.0)
    acceleration = MU_D * NORMAL_N / BLOCK_KG                       # 6 m/s^2: belt speed at 0.167 s
    fast = BELT_M_PER_S - v > 0.2
    assert fast.sum() > 100
    np.testing.assert_allclose(force[fast], MU_D * NORMAL_N, rtol=1e-6)
    np.testing.assert_allclose(v[fast], acceleration * t[fast], rtol=1e-6)
    assert abs(v[-1] - BELT_M_PER_S) < 1e-6 and abs(force[-1]) < 1e-6 * NORMAL_N    # carried along


@pytest.mark.parametrize("share", [0.5, 0.9])
def test_block_on_belt_sticks_below_static_friction(share):
    """A push against the belt's motion below mu_s N (0.9 mu_s N is above mu_d N): the block moves
    with the belt and friction balances the push."""
    friction = Friction(MU_D, FACT, DECAY_S_PER_M, regularisation_speed_m_per_s=1e-5)
    push = -share * FACT * MU_D * NORMAL_N
    _, v, force = _block_on_belt(friction, push, BELT_M_PER_S)
    np.testing.assert_allclose(force[-10:], -push, rtol=1e-9)
    # the regularised law carries the push at a creep of a few regularisation speeds (one step
    # of 1 ms to build it up from zero slip)
    assert np.max(np.abs(v - BELT_M_PER_S)) < 1e-3
    assert np.max(np.abs(v[-100:] - BELT_M_PER_S)) < 1e-4


@pytest.mark.mpi
def test_block_on_belt_breaks_away_above_static_friction():
    friction = Friction(MU_D, FACT, DECAY_S_PER_M, regularisation_speed_m_per_s=1e-5)
    push = -1.1 * FACT * MU_D * NORMAL_N
    t, v, force = _block_on_belt(friction, push, BELT_M_PER_S)
    fast = BELT_M_PER_S - v > 0.2
    assert fast.sum() > 50
    np.testing.assert_allclose(force[fast], MU_D * NORMAL_N, rtol=1e-6)
    # then decelerating at (mu_d N + push) / m
    slope = np.polyfit(t[fast], v[fast], 1)[0]
    assert slope == pytest.approx((MU_D * NORMAL_N + push) / BLOCK_KG, rel=1e-6)


def test_friction_force_cap():
    cap_N = 0.5 * MU_D * NORMAL_N
    friction = Friction(MU_D, FACT, DECAY_S_PER_M, shear_cap_Pa=cap_N, regularisation_speed_m_per_s=1e-5)
    t, v, force = _block_on_belt(friction, 0.0, 0.0)
    slipping = BELT_M_PER_S - v > 1e-3
    assert slipping.sum() > 100
    np.testing.assert_allclose(force[slipping], cap_N, rtol=1e-6)
    np.testing.assert_allclose(v[slipping], cap_N / BLOCK_KG * t[slipping], rtol=1e-6)
