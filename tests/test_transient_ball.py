"""Ball drop on a Kelvin-Voigt plane against the closed form, and hard contact cases that must
finish: 1000x stiffness, a ball chattering on a shaken elastic block, a grazing impact."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from app.transient.control import StepSizes
from app.transient.stepper import run_scene
from demos.demo_ball_drop import BallDrop, ball_drop_closed_form, ball_step_sizes, build_ball_drop, measured_impact
from demos.demo_vibrating_block import vibrating_block_with_ball
from forms.newmark import TimeScheme


@pytest.mark.parametrize("stiffness_factor", [1.0, 1000.0])
def test_ball_drop_matches_kelvin_voigt_closed_form(stiffness_factor):
    base = BallDrop()
    ball = dataclasses.replace(base, stiffness_N_per_m=base.stiffness_N_per_m * stiffness_factor,
                               damping_N_s_per_m=base.damping_N_s_per_m * np.sqrt(stiffness_factor))
    system, state = build_ball_drop(MPI.COMM_SELF, ball, TimeScheme.newmark())
    fall_s = np.sqrt(2 * ball.height_m / ball.gravity_m_per_s2)
    duration_cf, restitution_cf = ball_drop_closed_form(ball)
    records, _, stepper = run_scene(system, state, ball_step_sizes(ball), fall_s + 3 * duration_cf)
    duration, restitution = measured_impact(ball, records)
    assert duration == pytest.approx(duration_cf, rel=0.005)
    assert restitution == pytest.approx(restitution_cf, abs=0.002)
    assert restitution < 0.995      # the damper really dissipates
    assert stepper.stats.cutbacks == 0


def test_ball_drop_force_free_restitution_is_one_without_damping():
    ball = BallDrop(damping_N_s_per_m=0.0)
    system, state = build_ball_drop(MPI.COMM_SELF, ball, TimeScheme.newmark())
    fall_s = np.sqrt(2 * ball.height_m / ball.gravity_m_per_s2)
    duration_cf, restitution_cf = ball_drop_closed_form(ball)
    records, _, _ = run_scene(system, state, ball_step_sizes(ball), fall_s + 3 * duration_cf)
    duration, restitution = measured_impact(ball, records)
    assert restitution_cf == pytest.approx(1.0, abs=1e-9)
    assert restitution == pytest.approx(1.0, abs=2e-3)
    assert duration == pytest.approx(duration_cf, rel=0.01)


@pytest.mark.mpi
def test_ball_chattering_on_shaken_block_finishes():
    """Table acceleration A w^2 ~ 11 g at 3 kHz: the ball is thrown off and lands again, again."""
    system, state = vibrating_block_with_ball(MPI.COMM_WORLD, TimeScheme.generalized_alpha(0.7),
                                              amplitude_m=0.3e-6, frequency_Hz=3000.0)
    sizes = StepSizes(open_s=2.5e-6, closed_s=5e-7, change_s=5e-8, min_s=1e-12)
    records, final, stepper = run_scene(system, state, sizes, 4e-3)
    closed = np.array([r["contact_closed"][0] for r in records])
    impacts = int(np.sum(np.diff(closed) == 1))
    assert final.t == pytest.approx(4e-3)
    assert impacts >= 2
    heights = np.array([r["position_m"][1] for r in records])
    assert heights.max() > heights[0] + 1e-6           # it really flew
    assert np.all(np.isfinite(heights))


@pytest.mark.mpi
def test_grazing_impact_finishes():
    """The ball skims the block's top face with a tiny normal speed and a large tangential one."""
    system, state = vibrating_block_with_ball(MPI.COMM_WORLD, TimeScheme.generalized_alpha(0.7),
                                              amplitude_m=0.0, ball_gap_m=2e-8,
                                              ball_velocity_m_per_s=(1.0, -1e-4))
    sizes = StepSizes(open_s=2.5e-6, closed_s=5e-7, change_s=5e-8, min_s=1e-12)
    records, final, stepper = run_scene(system, state, sizes, 2e-3)
    assert final.t == pytest.approx(2e-3)
    assert any(r["contact_closed"][0] for r in records)
