"""The travelling-wave friction-drive reference (app.references.friction_drive) checked independently:
against space-time quadrature of Coulomb friction on a Winkler layer, against a slider integrated in
time under a load, and against its small-angle asymptote. Dimensionless units (omega = U_t = k = W
= k_w = mu = 1): the formula is homogeneous in each."""

import math

import numpy as np
import pytest

from app.references.friction_drive import (
    contact_half_angle,
    contact_integral,
    force_ratio,
    no_load_speed,
    speed_for_force,
)

THETA_C = 0.8           # contact half-angle [rad]


def _layer(n_points: int):
    x = (np.arange(n_points) + 0.5) * 2 * math.pi / n_points
    return x, 2 * math.pi / n_points


def _friction_force(t: float, speed: float, x: np.ndarray, dx: float, slip_width: float) -> float:
    """Sum over a wavelength of mu * pressure * sign(slip): the stator surface w = cos(x - t),
    u = sin(x - t) (tangential velocity du/dt = -cos(x - t): the crest moves towards -x, the drive
    direction), the slider at height cos(THETA_C), moving at ``speed`` towards -x."""
    xi = x - t
    pressure = np.maximum(np.cos(xi) - math.cos(THETA_C), 0.0)
    tangential_velocity = -np.cos(xi)                   # along +x
    surface_speed_in_drive_direction = -tangential_velocity
    slip = surface_speed_in_drive_direction - speed
    return float(np.sum(pressure * np.tanh(slip / slip_width)) * dx)


def test_normal_force_and_half_angle_round_trip():
    n = 2 * contact_integral(THETA_C)          # per wavelength, k_w = W = k = 1
    assert contact_half_angle(n, 1.0, 1.0, 1.0) == pytest.approx(THETA_C, rel=1e-12)
    x, dx = _layer(20000)
    assert np.sum(np.maximum(np.cos(x) - math.cos(THETA_C), 0.0)) * dx == pytest.approx(n, rel=1e-6)


def test_force_law_matches_space_time_quadrature():
    x, dx = _layer(8000)
    normal = 2 * contact_integral(THETA_C)
    for speed in (0.0, 0.5, 0.75, 0.8, 0.9, 0.95, 1.05):
        mean = np.mean([_friction_force(t, speed, x, dx, 1e-9) for t in np.linspace(0, 2 * math.pi, 16,
                                                                                      endpoint=False)])
        assert mean / normal == pytest.approx(force_ratio(speed, 1.0, THETA_C), abs=2e-3), speed
    # plateaus: every contact point slides forward below omega U_t cos theta_c, backward above omega U_t
    assert force_ratio(0.0, 1.0, THETA_C) == pytest.approx(1.0, abs=1e-12)
    assert force_ratio(math.cos(THETA_C) * 0.999, 1.0, THETA_C) == pytest.approx(1.0, abs=1e-12)
    assert force_ratio(1.2, 1.0, THETA_C) == -1.0


@pytest.mark.parametrize("points, periods, start, rtol", [
    (1000, 8, 0.999, 1e-3),
    pytest.param(4000, 30, 0.99, 2e-4, marks=pytest.mark.slow, id="fine"),
])
def test_loaded_slider_reaches_the_predicted_speed(points, periods, start, rtol):
    """A slider of mass m under a constant load, integrated in time with a narrow (1e-4 omega U_t)
    regularisation of Coulomb's law, settles at the speed where the mean force balances the load.
    Tolerance: the layer's midpoint quadrature is first order where the friction switches sign along
    the moving contact (the speed error at load 0.5 is 4.4e-4 with 1000 points, < 2e-4 with 4000), and
    the slider started at ``start`` times the law's speed settles with the time constant m / (dF/dV)
    (8 periods from 0.999 leave 1.3e-4). The CI version (1000 points, 8 periods, 20 s) gets 1e-3, the
    slow one (4000 points, 30 periods from 0.99, ~3.5 min) 2e-4."""
    from scipy.integrate import solve_ivp

    x, dx = _layer(points)
    normal = 2 * contact_integral(THETA_C)
    mass = 50.0                                 # speed ripple over a period ~1e-5 of omega U_t
    for load_ratio in (0.0, 0.5):
        expected = speed_for_force(load_ratio, 1.0, THETA_C) if load_ratio else no_load_speed(1.0, THETA_C)
        load = load_ratio * normal
        solution = solve_ivp(lambda t, y, load=load: [(_friction_force(t, y[0], x, dx, 1e-4) - load) / mass],
                             (0.0, 2 * math.pi * periods), [start * expected], method="LSODA", rtol=1e-9, atol=1e-12)
        last = solution.t > solution.t[-1] - 2 * math.pi * 5
        mean_speed = np.trapz(solution.y[0][last], solution.t[last]) / (solution.t[last][-1] - solution.t[last][0])
        assert mean_speed == pytest.approx(expected, rel=rtol), load_ratio


def test_no_load_speed_small_angle_asymptote():
    """V_0 / (omega U_t) = cos(a theta_c), a the root of a^3 - 3 a + 1 = 0 in (0, 1): 1 - 0.0603 theta_c^2."""
    a = min(r.real for r in np.roots([1, 0, -3, 1]) if 0 < r.real < 1)
    for theta in (0.05, 0.1):
        deficit = 1 - no_load_speed(1.0, theta)
        assert deficit == pytest.approx(a * a / 2 * theta**2, rel=2e-2 * (theta / 0.05) ** 2)
    assert a * a / 2 == pytest.approx(0.0603, abs=1e-4)
