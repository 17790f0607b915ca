"""A rigid ball dropped on a Kelvin-Voigt foundation, against the closed form.

A steel ball falls from 1 mm onto a rigid plane through a linear spring-damper contact that cannot
pull (app.transient.contact.PointContact between two rigid bodies, no FE part). During contact
m x'' + c x' + k x = m g with x(0) = 0, x'(0) = v_in; the contact ends where k x + c x' returns to
zero. :func:`ball_drop_closed_form` gives that duration and the coefficient of restitution; the demo
measures both from the time steps (crossings located by linear interpolation) and compares.

    python demos/demo_ball_drop.py               # or: mpirun -n 2 python demos/demo_ball_drop.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # runnable as ``python demos/<this file>``

import math  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

from app.transient.contact import PointContact  # noqa: E402
from app.transient.control import StepSizes  # noqa: E402
from app.transient.coupled import CoupledSystem  # noqa: E402
from app.transient.rigid import RigidBody, RigidSet, fixed_body  # noqa: E402
from app.transient.state import TransientState  # noqa: E402
from app.transient.stepper import run_scene  # noqa: E402
from forms.newmark import TimeScheme  # noqa: E402

STEEL_DENSITY_kg_per_m3 = 7850.0
# 200 steps per contact: the duration to 0.5 %, the restitution to 0.002 (the measured crossings are
# linear interpolations between steps).
DURATION_RTOL = 0.005
RESTITUTION_ATOL = 0.002


@dataclass(frozen=True)
class BallDrop:
    """Rigid steel ball dropped from ``height_m`` (gap) onto a rigid plane through a linear
    Kelvin-Voigt contact (stiffness k, damping c; no pull)."""

    diameter_m: float = 8e-3
    height_m: float = 1e-3
    stiffness_N_per_m: float = 1e7
    damping_N_s_per_m: float = 2.0
    gravity_m_per_s2: float = 9.81

    @property
    def mass_kg(self) -> float:
        return STEEL_DENSITY_kg_per_m3 * math.pi / 6 * self.diameter_m**3

    @property
    def impact_speed_m_per_s(self) -> float:
        return math.sqrt(2 * self.gravity_m_per_s2 * self.height_m)


def ball_drop_closed_form(ball: BallDrop) -> tuple[float, float]:
    """(contact duration [s], coefficient of restitution) of the linear Kelvin-Voigt contact with
    force clipped at zero, gravity included: during contact m x'' + c x' + k x = m g (x penetration)
    with x(0) = 0, x'(0) = v_in; contact ends at the first t > 0 with k x + c x' = 0."""
    m, k, c, g = ball.mass_kg, ball.stiffness_N_per_m, ball.damping_N_s_per_m, ball.gravity_m_per_s2
    v_in = ball.impact_speed_m_per_s
    w0 = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = w0 * math.sqrt(1 - zeta**2)
    x_static = m * g / k
    # x(t) = x_s + e^{-zeta w0 t} (A cos wd t + B sin wd t), A = -x_s, B = (v_in + zeta w0 A) / wd
    A = -x_static
    Bc = (v_in + zeta * w0 * A) / wd

    def x(t):
        return x_static + math.exp(-zeta * w0 * t) * (A * math.cos(wd * t) + Bc * math.sin(wd * t))

    def xd(t):
        e = math.exp(-zeta * w0 * t)
        return e * ((-zeta * w0 * A + wd * Bc) * math.cos(wd * t) + (-zeta * w0 * Bc - wd * A) * math.sin(wd * t))

    def force(t):
        return k * x(t) + c * xd(t)

    from scipy.optimize import brentq

    # The force returns to zero near the half period (before it with damping, just after it
    # without damping because gravity holds the ball down); it has no other zero in between.
    t_hi = 1.5 * math.pi / wd
    t_lo = 0.25 * t_hi
    duration = brentq(force, t_lo, t_hi, xtol=1e-15, rtol=1e-13)
    return duration, -xd(duration) / v_in


def build_ball_drop(comm, ball: BallDrop, scheme: TimeScheme):
    """Rigid ball on a rigid plane, 1D vertical (gdim 1: no FE part) -> (system, state)."""
    ball_body = RigidBody("ball", ball.mass_kg, [ball.height_m + ball.diameter_m / 2], [0.0],
                          [-ball.gravity_m_per_s2])
    ground = fixed_body("ground", [0.0])
    rigid = RigidSet([ground, ball_body])
    link = PointContact("ball_ground", "ground", "ball", [1.0], ball.diameter_m / 2,
                        ball.stiffness_N_per_m, ball.damping_N_s_per_m)
    system = CoupledSystem(comm, scheme, None, rigid, [link])
    z, zd, zdd = rigid.initial_state()
    empty = np.zeros(0)
    return system, TransientState(0.0, empty, empty, empty, z, zd, zdd)


def ball_step_sizes(ball: BallDrop, steps_per_contact: int = 200) -> StepSizes:
    contact = math.pi * math.sqrt(ball.mass_kg / ball.stiffness_N_per_m)
    dt = contact / steps_per_contact
    # Free flight is exact for the scheme (constant gravity), so open steps are long; closure is
    # approached by the controller's time-to-contact rule.
    return StepSizes(open_s=2**12 * dt, closed_s=dt, change_s=dt / 8, min_s=dt / 2**16)


def measured_impact(ball: BallDrop, records):
    """(contact duration [s], restitution) of the first impact: contact starts where the penetration
    crosses zero and ends where the unclipped Kelvin-Voigt force k delta + c delta' does (both located
    by linear interpolation between steps), as in the closed form."""
    t = np.array([r["time_s"] for r in records])
    z = np.array([r["position_m"][1] for r in records])
    v = np.array([r["velocity_m_per_s"][1] for r in records])
    penetration = ball.diameter_m / 2 - z
    kv_force = ball.stiffness_N_per_m * penetration - ball.damping_N_s_per_m * v

    def crossing(q, i):     # zero of q between records i-1 and i
        return t[i - 1] + (t[i] - t[i - 1]) * q[i - 1] / (q[i - 1] - q[i])

    start = int(np.argmax(penetration > 0))
    end = start + int(np.argmax(kv_force[start:] < 0))
    t_in, t_out = crossing(penetration, start), crossing(kv_force, end)
    g = ball.gravity_m_per_s2
    v_in = v[start - 1] - g * (t_in - t[start - 1])
    v_out = v[end - 1] + (v[end] - v[end - 1]) * (t_out - t[end - 1]) / (t[end] - t[end - 1])
    return t_out - t_in, -v_out / v_in


def main(comm=MPI.COMM_WORLD) -> dict:
    ball = BallDrop()
    system, state = build_ball_drop(comm, ball, TimeScheme.newmark())
    fall_s = math.sqrt(2 * ball.height_m / ball.gravity_m_per_s2)
    duration_cf, restitution_cf = ball_drop_closed_form(ball)
    records, _, _ = run_scene(system, state, ball_step_sizes(ball), fall_s + 3 * duration_cf)
    system.destroy()
    duration, restitution = measured_impact(ball, records)
    if comm.rank == 0:
        print(f"contact duration {duration * 1e6:.4f} us (closed form {duration_cf * 1e6:.4f} us), "
              f"restitution {restitution:.5f} (closed form {restitution_cf:.5f})")
    return {"duration_s": duration, "expected_duration_s": duration_cf,
            "restitution": restitution, "expected_restitution": restitution_cf}


def check(result: dict) -> None:
    assert math.isclose(result["duration_s"], result["expected_duration_s"], rel_tol=DURATION_RTOL), result
    assert abs(result["restitution"] - result["expected_restitution"]) <= RESTITUTION_ATOL, result


if __name__ == "__main__":
    check(main())
