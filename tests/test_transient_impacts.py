"""Impact statistics of a transient run (app/transient/impacts.py) against conservation laws: a
damped ball dropped on a Kelvin-Voigt foundation bounces and the foundation's impulse is the ball's
weight times the time plus its final momentum (momentum balance), while the work done on the
foundation is the mechanical energy the ball lost (energy balance); and the drive-period average
removes a vibration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from app.case.transient import BodySection, PointContactSection, TransientSection
from app.transient.control import StepSizes
from app.transient.impacts import closed_intervals, period_average, run_statistics
from app.transient.stepper import run_scene
from demos.demo_ball_drop import BallDrop, build_ball_drop
from forms.newmark import TimeScheme


def _series(records, bodies, contacts) -> dict[str, np.ndarray]:
    """The rows the transient driver writes to transient.h5, from stepper records."""
    data = {"time_s": np.array([r["time_s"] for r in records]), "dt_s": np.array([r["dt_s"] for r in records])}
    for name, sl in bodies.items():
        data[f"{name}_position_m"] = np.array([r["position_m"][sl] for r in records])
        data[f"{name}_velocity_m_per_s"] = np.array([r["velocity_m_per_s"][sl] for r in records])
    for j, name in enumerate(contacts):
        data[f"{name}_force_N"] = np.array([r["contact_force_N"][name] for r in records])
        data[f"{name}_closed"] = np.array([float(r["contact_closed"][j]) for r in records])
    return data


def test_closed_intervals_and_period_average():
    assert closed_intervals(np.array([0, 1, 1, 0, 0, 1, 0, 1])) == [(1, 2), (5, 5), (7, 7)]
    period = 1 / 20e3
    t = np.sort(np.random.default_rng(1).uniform(0.0, 40 * period, 4000))
    drift = 3e-3 * t / t[-1]
    t_mean, z_mean = period_average(t, drift + 15e-6 * np.sin(2 * math.pi * t / period), period, 64)
    inside = (t_mean > 2 * period) & (t_mean < 38 * period)
    assert np.max(np.abs(z_mean[inside] - 3e-3 * t_mean[inside] / t[-1])) < 0.02 * 15e-6


def test_foundation_statistics_close_momentum_and_energy():
    ball = BallDrop(damping_N_s_per_m=150.0)          # damping ratio ~0.5: two or three bounces
    system, state = build_ball_drop(MPI.COMM_SELF, ball, TimeScheme.generalized_alpha(0.8))
    contact_s = math.pi * math.sqrt(ball.mass_kg / ball.stiffness_N_per_m)
    sizes = StepSizes(open_s=contact_s / 4, closed_s=contact_s / 50, change_s=contact_s / 400, min_s=1e-15)
    end_s = 0.025
    records, final, _ = run_scene(system, state, sizes, end_s)
    data = _series(records, {"ball": system.rigid.dofs("ball")}, ["ball_ground"])
    cfg = TransientSection(
        end_time_s=end_s, output_interval_s=end_s,
        bodies=[BodySection(name="ground", position_m=[0.0], fixed=True),
                BodySection(name="ball", position_m=[ball.height_m + ball.diameter_m / 2], mass_kg=ball.mass_kg)],
        contacts=[PointContactSection(name="ball_ground", kind="point", stiffness=ball.stiffness_N_per_m,
                                 damping=ball.damping_N_s_per_m, lower="ground", upper="ball", direction=[1.0],
                                 touch_distance_m=ball.diameter_m / 2)])
    stats = run_statistics(data, cfg)
    found = stats["ball_ground_foundation"]
    assert stats["impact_count"]["ball_ground"] >= 2              # it bounced
    weight = ball.mass_kg * ball.gravity_m_per_s2
    v_end = final.zd[1]
    # momentum: integral of the foundation force = m g T + m v(T) (the ball starts at rest); the
    # sum of mid-point forces x dt matches m dv only to O(dt) when dt changes (event refinements)
    assert found["mean_force_N"] * end_s == pytest.approx(weight * end_s + ball.mass_kg * v_end, rel=5e-3)
    # energy: work done on the foundation (absorbed + stored) = potential energy lost - kinetic energy
    lost = weight * (ball.height_m + ball.diameter_m / 2 - final.z[1]) - 0.5 * ball.mass_kg * v_end**2
    assert found["mean_power_W"] * end_s == pytest.approx(lost, rel=5e-3)
    assert stats["bodies"]["ball"]["max_rise_m"] == pytest.approx(0.0, abs=1e-12)
