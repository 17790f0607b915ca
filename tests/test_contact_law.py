"""The contact law is written once (forms/contact.py, UFL) and its scalar twins (forms/contact_law.py) are
the same law: at sample points of every branch (open, penetrating, rounded start, clipped damper, stick,
slip, capped, static-to-kinetic decay) the UFL expressions, evaluated by dolfinx on a one-cell mesh whose
measure is 1, equal the scalar functions to round-off, values and derivatives (the UFL derivative of the
form against the scalar's own). A law changed in one place and not the other fails here."""

from __future__ import annotations

import math

import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI

from forms import contact as cf
from forms import contact_law as law


@pytest.fixture(scope="module")
def unit_cell():
    return mesh.create_unit_interval(MPI.COMM_SELF, 1)


def value(domain, expr) -> float:
    """The value of a constant UFL expression: its integral over the unit interval."""
    return fem.assemble_scalar(fem.form(expr * ufl.dx(domain=domain)))


def constant(domain, x):
    return fem.Constant(domain, float(x))


K, C = 4e13, 2e5          # penalty [Pa/m], damping [Pa s/m]
ROUNDING = 1e-9           # [m]


@pytest.mark.parametrize("rounding", [0.0, ROUNDING])
@pytest.mark.parametrize("gap, rate", [(1e-9, -1.0), (-3e-10, 0.0), (-3e-10, -1e-3), (-2e-8, 0.02),
                                       (-2e-8, 1e4), (-5e-9, -0.5)])
def test_penalty_pressure_ufl_and_scalar_agree(unit_cell, gap, rate, rounding):
    g, r = constant(unit_cell, gap), constant(unit_cell, rate)
    gv, rv = ufl.variable(g), ufl.variable(r)
    p = cf.normal_pressure(gv, rv, K, C, rounding)
    expected, dp_dg, dp_dr = law.penalty_pressure(gap, rate, K, C, rounding)
    scale = K * 2e-8
    assert value(unit_cell, p) == pytest.approx(expected, rel=1e-12, abs=1e-12 * scale)
    assert value(unit_cell, ufl.diff(p, gv)) == pytest.approx(dp_dg, rel=1e-12, abs=1e-12 * K)
    assert value(unit_cell, ufl.diff(p, rv)) == pytest.approx(dp_dr, rel=1e-12, abs=1e-12 * C)
    energy = cf.penalty_energy_density(g, K, rounding)
    assert value(unit_cell, energy) == pytest.approx(law.penalty_energy(gap, K, rounding), rel=1e-12,
                                                     abs=1e-12 * K * 4e-16)


def test_rounded_pressure_is_continuous_with_a_continuous_slope():
    """C^1 at first touch and at the end of the rounding: the reason the rounding exists."""
    below = law.penalty_pressure(-ROUNDING * (1 - 1e-9), 0.0, K, 0.0, ROUNDING)
    above = law.penalty_pressure(-ROUNDING * (1 + 1e-9), 0.0, K, 0.0, ROUNDING)
    assert below[0] == pytest.approx(above[0], rel=1e-6)
    assert below[1] == pytest.approx(above[1], rel=1e-6)
    touch = law.penalty_pressure(-1e-30, 0.0, K, 0.0, ROUNDING)
    assert touch[0] < 1e-30 * K and abs(touch[1]) < 1e-20 * K
    # the energy is the integral of the elastic pressure
    d = 3.7e-9
    h = 1e-13
    de = (law.penalty_energy(-(d + h), K, ROUNDING) - law.penalty_energy(-(d - h), K, ROUNDING)) / (2 * h)
    assert de == pytest.approx(law.penalty_pressure(-d, 0.0, K, 0.0, ROUNDING)[0], rel=1e-6)


FRICTION = [law.FrictionLaw(0.57), law.FrictionLaw(0.57, 1.298, 50.0, 124.13e6, 1e-4),
            law.FrictionLaw(0.57, 1.298, 50.0, 2e5, 1e-4)]


@pytest.mark.parametrize("friction", FRICTION, ids=["coulomb", "decay", "capped"])
@pytest.mark.parametrize("slip", [(2e-6, -1e-6, 0.0), (3e-5, 4e-5, 0.0), (0.2, -0.05, 0.0), (0.0, 0.0, 0.0)])
def test_friction_traction_ufl_and_scalar_agree(unit_cell, friction, slip):
    """t = -min(mu(|s|) p, cap) s / sqrt(|s|^2 + eps^2), with the slip in the tangent plane of n = e_z, and the
    scalar twin's shear and its derivatives (d tau / d|s|, d tau / dp) against the UFL derivatives."""
    pressure = 1.5e6
    n = ufl.as_vector((0.0, 0.0, 1.0))
    s_const = [constant(unit_cell, c) for c in slip]
    s_vars = [ufl.variable(c) for c in s_const]
    p_var = ufl.variable(constant(unit_cell, pressure))
    velocity = ufl.as_vector(s_vars) + 7.0 * n            # a normal velocity component: projected out
    traction = cf.friction_traction(n, velocity, p_var, *friction)
    s = np.array(slip)
    speed_sq = float(s @ s)
    speed = law.slip_speed(speed_sq)
    tau, dtau_dspeed, dtau_dp = law.friction_shear(speed, pressure, friction.mu_dynamic, friction.static_ratio,
                                                   friction.decay_s_per_m, friction.shear_cap_Pa)
    reg = law.regularised_speed(speed_sq, friction.regularisation_speed_m_per_s)
    expected = -tau * s / reg
    scale = friction.mu_dynamic * friction.static_ratio * pressure
    for k in range(3):
        assert value(unit_cell, traction[k]) == pytest.approx(expected[k], abs=1e-12 * scale)
    # d t / d p = -(d tau / dp) s / reg
    for k in range(3):
        assert value(unit_cell, ufl.diff(traction[k], p_var)) == pytest.approx(-dtau_dp * s[k] / reg,
                                                                                abs=1e-12 * friction.static_ratio)
    # d t / d s = -tau (I / reg - s s^T / reg^3) - (s / reg) (d tau / d|s|) s^T / |s|
    jac = -tau * (np.eye(3) / reg - np.outer(s, s) / reg**3) - np.outer(s / reg, s / speed) * dtau_dspeed
    for k in range(2):
        for j in range(2):
            got = value(unit_cell, ufl.diff(traction[k], s_vars[j]))
            assert got == pytest.approx(jac[k, j], rel=1e-10, abs=1e-10 * scale / friction.regularisation_speed_m_per_s)


def test_static_to_kinetic_decay():
    """mu(0) = FACT mu_d, mu -> mu_d at high slip speed, and the derivative of the scalar coefficient."""
    mu0, _ = law.friction_coefficient(0.0, 0.57, 1.298, 50.0)
    assert mu0 == pytest.approx(0.57 * 1.298, rel=1e-15)
    assert law.friction_coefficient(10.0, 0.57, 1.298, 50.0)[0] == pytest.approx(0.57, rel=1e-15)
    h, speed = 1e-7, 0.013
    fd = (law.friction_coefficient(speed + h, 0.57, 1.298, 50.0)[0]
          - law.friction_coefficient(speed - h, 0.57, 1.298, 50.0)[0]) / (2 * h)
    assert law.friction_coefficient(speed, 0.57, 1.298, 50.0)[1] == pytest.approx(fd, rel=1e-6)
    assert math.isclose(law.friction_shear(0.0, 2.0, 0.57, 1.298, 50.0, 0.5)[0], 0.5)       # the cap
