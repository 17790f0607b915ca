"""Energy each interaction dissipates (``<contact>_dissipated_J``; app/transient/stepper.py integrates
the damping and friction power of every interaction at the step mid-point).

Here the rigid-rigid Kelvin-Voigt link of the ball drop (demos/demo_ball_drop.py): no FE part, no
friction, so the mechanical energy the ball loses over a bounce (kinetic + gravity, the contact open
before and after) is exactly what the damper takes, including the elastic energy left in the link
when its clipped force lets go. The surface contact's friction power is checked against the
friction-drive law in tests/test_strip_friction_drive.py."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from forms.newmark import TimeScheme

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "demos"))
from demo_ball_drop import BallDrop, ball_drop_closed_form, ball_step_sizes, build_ball_drop  # noqa: E402

from app.transient.stepper import run_scene  # noqa: E402


@pytest.mark.mpi
@pytest.mark.parametrize("damping_N_s_per_m", [0.0, 2.0, 20.0])
def test_link_dissipates_the_energy_the_bounce_loses(damping_N_s_per_m):
    ball = BallDrop(damping_N_s_per_m=damping_N_s_per_m)
    system, state = build_ball_drop(MPI.COMM_WORLD, ball, TimeScheme.newmark())
    fall_s = np.sqrt(2 * ball.height_m / ball.gravity_m_per_s2)
    duration, restitution = ball_drop_closed_form(ball)
    records, final, _ = run_scene(system, state, ball_step_sizes(ball), fall_s + 3 * duration)
    system.destroy()
    m, g = ball.mass_kg, ball.gravity_m_per_s2

    def mechanical_J(rec):
        return 0.5 * m * rec["velocity_m_per_s"][1] ** 2 + m * g * rec["position_m"][1]

    assert not records[-1]["contact_closed"][0]              # the ball flies again
    lost = mechanical_J({"velocity_m_per_s": state.zd, "position_m": state.z}) - mechanical_J(records[-1])
    dissipated = records[-1]["dissipated_J"]["ball_ground"]
    impact_J = 0.5 * m * ball.impact_speed_m_per_s**2
    # the closed form's restitution: the kinetic energy the bounce takes, to the gravity work within it
    assert dissipated == pytest.approx(impact_J * (1 - restitution**2), abs=2e-3 * impact_J)
    # the energy balance of the trapezoidal rule: to its accuracy at 200 steps per contact
    assert dissipated == pytest.approx(lost, abs=1e-4 * impact_J)
    if damping_N_s_per_m == 0.0:
        assert dissipated == pytest.approx(0.0, abs=1e-9 * impact_J)
    else:
        assert dissipated > 0.01 * impact_J
