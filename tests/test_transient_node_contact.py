"""Node-to-body Hertz contact: a rigid ball hitting one node of a (nearly rigid) elastic block has
the closed-form Hertz impact, and the tiny drill scene sees ball-tip impacts through its axis node."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI
from scipy.special import beta

from app.transient.contact import NodeContact
from app.transient.control import StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.fe import LinearFE
from app.transient.rigid import RigidBody, RigidSet
from app.transient.state import TransientState
from app.transient.stepper import run_scene
from demos.demo_vibrating_block import elastic_block
from forms.newmark import TimeScheme

HERTZ_N_PER_M1_5 = 1e9
BALL_KG = 2e-3
SPEED_M_PER_S = 0.5


def hertz_impact(m, k, v):
    """(duration [s], max penetration [m]) of m x'' = -k x^1.5, x(0) = 0, x'(0) = v."""
    delta_max = (5 * m * v * v / (4 * k)) ** 0.4
    return 2 * delta_max / v * 0.4 * beta(0.4, 0.5), delta_max


def block_with_node_contact(comm, young_Pa):
    width, height = 10e-3, 5e-3
    V, mass_form, stiffness_form, base = elastic_block(comm, 4, 2, young_Pa, width, height)
    zero = fem.Function(V)
    bc = fem.dirichletbc(zero, fem.locate_dofs_topological(V, 1, base))
    fe = LinearFE(V, V, mass_form, stiffness_form, bcs=[bc])
    radius = 4e-3
    ball = RigidBody("ball", BALL_KG, [width / 2, height + radius + 1e-7], [0.0, -SPEED_M_PER_S], [0.0, 0.0],
                     prescribed_axes=(True, False))
    rigid = RigidSet([ball])
    contact = NodeContact("top_ball", fe, [width / 2, height], "ball", radius, [0.0, -1.0], HERTZ_N_PER_M1_5)
    system = CoupledSystem(comm, TimeScheme.newmark(), fe, rigid, [contact])
    z, zd, zdd = rigid.initial_state()
    n = fem.Function(V).x.array.size
    return system, TransientState(0.0, np.zeros(n), np.zeros(n), np.zeros(n), z, zd, zdd)


@pytest.mark.mpi
def test_ball_on_a_node_follows_the_hertz_closed_form():
    # A block 10^4 x stiffer than steel: its compliance is negligible next to the Hertz spring.
    system, state = block_with_node_contact(MPI.COMM_WORLD, 200e9 * 1e4)
    duration_cf, delta_cf = hertz_impact(BALL_KG, HERTZ_N_PER_M1_5, SPEED_M_PER_S)
    dt = duration_cf / 400
    sizes = StepSizes(open_s=16 * dt, closed_s=dt, change_s=dt / 8, min_s=dt / 2**16)
    records, _, stepper = run_scene(system, state, sizes, 1.5 * duration_cf)
    t = np.array([r["time_s"] for r in records])
    force = np.array([r["contact_force_N"]["top_ball"][1] for r in records])     # on the ball, +y
    on = np.flatnonzero(force > 0)
    assert on.size > 100
    duration = t[on[-1]] - t[on[0]] + 0.5 * (t[on[0]] - t[on[0] - 1]) + 0.5 * (t[on[-1] + 1] - t[on[-1]])
    assert duration == pytest.approx(duration_cf, rel=0.01)
    peak_cf = HERTZ_N_PER_M1_5 * delta_cf**1.5
    assert force.max() == pytest.approx(peak_cf, rel=0.01)
    v_out = records[-1]["velocity_m_per_s"][1]
    assert v_out == pytest.approx(SPEED_M_PER_S, rel=0.01)          # elastic: restitution 1
    assert stepper.stats.cutbacks == 0
    assert math.isfinite(v_out)


def test_node_contact_rejects_a_bad_normal():
    system, _ = block_with_node_contact(MPI.COMM_SELF, 200e9)
    with pytest.raises(ValueError, match="unit vector"):
        NodeContact("c", system.fe, [5e-3, 5e-3], "ball", 4e-3, [0.0, 2.0], 1e9)
