"""Lumped drill model against closed forms: Kelvin-Voigt impact under the force-zero opening rule,
free flight, energy ledger, event location at tiny penetration and grazing, chattering."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from app.case.lumped import LumpedSection
from app.case.validate import from_dict
from app.lumped import kernel as K
from app.lumped.model import ID2, ID3, IW, IX, IZ
from app.lumped.parameters import (
    contact_duration_s,
    damping_ratio_from_restitution,
    derive_parameters,
    effective_modulus_Pa,
    hertz_secant_stiffness_N_per_m,
    restitution_from_damping_ratio,
)
from app.lumped.simulate import initial_state_from_section, simulate


def run(data: dict):
    section = from_dict(LumpedSection, data, "test.toml", "lumped")
    p = derive_parameters(section)
    result = simulate(
        p,
        section.duration_s,
        initial_state_from_section(p, section.initial),
        section.output.output_interval_s,
        section.solver,
    )
    return section, p, result


def closings(result, contact):
    ev = result.events
    return ev[(ev[:, K.EV_CONTACT] == contact) & (ev[:, K.EV_CLOSING] == 1.0)]


def openings(result, contact):
    ev = result.events
    return ev[(ev[:, K.EV_CONTACT] == contact) & (ev[:, K.EV_CLOSING] == 0.0)]


def stem_drop(approach_velocity, damping, stiffness=2.0e8, duration=2e-4):
    """Stem falling onto the rock layer without gravity; transducer and ball far above and at rest."""
    return {
        "duration_s": duration,
        "gravity_m_per_s2": 0.0,
        "drive": {"voltage_amplitude_V": 0.0},
        "stem": {"mass_kg": 0.04},
        "contact_stem_rock": {
            "stiffness_rule": "given",
            "stiffness_N_per_m": stiffness,
            "damping_N_s_per_m": damping,
        },
        "initial": {
            "vibration": "rest",
            "transducer_z_m": 0.02,
            "free_mass_w_m": 0.01,
            "stem_v_m": approach_velocity * 1e-5,
            "stem_velocity_m_per_s": -approach_velocity,
        },
        "output": {"output_interval_s": 1e-6},
    }


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.3, 0.9, 1.0, 1.7])
def test_kelvin_voigt_impact_matches_closed_form(zeta):
    mass, stiffness, v0 = 0.04, 2.0e8, 1.0
    damping = 2 * zeta * math.sqrt(stiffness * mass)
    _, _, result = run(stem_drop(v0, damping, stiffness))
    close, open_ = closings(result, 2), openings(result, 2)
    assert len(close) == 1 and len(open_) == 1
    t_close = v0 * 1e-5 / v0
    assert close[0, K.EV_TIME] == pytest.approx(t_close, abs=1e-13)
    assert close[0, K.EV_REL_VELOCITY] == pytest.approx(v0, rel=1e-12)  # approach: p3' = -v' > 0
    duration = open_[0, K.EV_TIME] - close[0, K.EV_TIME]
    assert duration == pytest.approx(contact_duration_s(stiffness, damping, mass), rel=1e-9)
    restitution = -open_[0, K.EV_REL_VELOCITY] / close[0, K.EV_REL_VELOCITY]
    assert restitution == pytest.approx(restitution_from_damping_ratio(zeta), rel=1e-9)
    # impulse = m (1 + e) v0 without gravity
    assert open_[0, K.EV_IMPULSE] == pytest.approx(mass * (1 + restitution) * v0, rel=1e-9)


def test_opening_before_geometric_separation_and_rock_relaxation():
    """A damped layer opens at zero force while still compressed; then c_u s' + k_u s = 0 (eq. 16)."""
    mass, stiffness, zeta = 0.04, 2.0e8, 0.3
    damping = 2 * zeta * math.sqrt(stiffness * mass)
    _, _, result = run(stem_drop(1.0, damping, stiffness))
    t_open = openings(result, 2)[0, K.EV_TIME]
    t, y = result.samples_t_s, result.samples_y
    after = t > t_open
    first = np.argmax(after)
    compression_at_open = y[first, ID3] * math.exp(stiffness / damping * (t[first] - t_open))
    assert compression_at_open > 1e-7  # the layer still holds ~ 0.1 um when the force vanishes
    expected = compression_at_open * np.exp(-stiffness / damping * (t[after] - t_open))
    np.testing.assert_allclose(y[after, ID3], expected, rtol=1e-8, atol=1e-22)


def test_restitution_inverse_and_hertz_secant():
    for e in (0.99, 0.8, 0.5, math.exp(-2.0), 0.05):
        assert restitution_from_damping_ratio(damping_ratio_from_restitution(e)) == pytest.approx(
            e, rel=1e-12
        )
    # continuity across critical damping
    assert restitution_from_damping_ratio(1 - 1e-7) == pytest.approx(
        restitution_from_damping_ratio(1 + 1e-7), rel=1e-5
    )
    e_star = effective_modulus_Pa(210e9, 0.3, 210e9, 0.3)
    k = hertz_secant_stiffness_N_per_m(4e-3, e_star, 300.0)
    delta = 300.0 / k
    assert 4.0 / 3.0 * e_star * math.sqrt(4e-3) * delta**1.5 == pytest.approx(300.0, rel=1e-12)


def test_tiny_penetration_event_is_located():
    """Approach at 1e-9 m/s: penetration ~1e-14 m, yet one impact with the closed-form e and duration."""
    mass, stiffness, zeta = 0.04, 2.0e8, 0.3
    damping = 2 * zeta * math.sqrt(stiffness * mass)
    _, _, result = run(stem_drop(1e-9, damping, stiffness))
    close, open_ = closings(result, 2), openings(result, 2)
    assert len(close) == 1 and len(open_) == 1
    duration = open_[0, K.EV_TIME] - close[0, K.EV_TIME]
    assert duration == pytest.approx(contact_duration_s(stiffness, damping, mass), rel=1e-8)
    restitution = -open_[0, K.EV_REL_VELOCITY] / close[0, K.EV_REL_VELOCITY]
    assert restitution == pytest.approx(restitution_from_damping_ratio(zeta), rel=1e-7)
    assert np.max(result.samples_y[:, ID3]) < 2e-13


@pytest.mark.parametrize("clearance_m, expect_contact", [(1e-12, False), (-1e-12, True)])
def test_grazing_tip_touches_ball_only_when_it_reaches_it(clearance_m, expect_contact):
    """Vibrating tip above a ball at rest (no gravity): the gap is amplitude-exact, so a 1 pm
    clearance must give no contact and a 1 pm overlap a contact at the tip's lowest point."""
    data = {"duration_s": 2e-4, "gravity_m_per_s2": 0.0, "output": {"output_interval_s": 1e-6}}
    amplitude = derive_parameters(
        from_dict(LumpedSection, data, "test.toml", "lumped")
    ).free_tip_amplitude_m()
    data["initial"] = {
        "transducer_z_m": 2e-3 + amplitude + clearance_m,
        "free_mass_w_m": 2e-3,
        "stem_v_m": 1e-3,
    }
    _, p, result = run(data)
    close = closings(result, 0)
    assert (len(close) > 0) == expect_contact
    if expect_contact:
        # first lowest point of x(t) = A sin(omega t + phi)
        x0, xd0 = result.initial_y[IX], result.initial_y[IX + 1]
        omega = p.drive_angular_frequency_rad_per_s
        phase = math.atan2(x0 * omega, xd0)
        t_low = ((1.5 * math.pi - phase) % (2 * math.pi)) / omega
        assert close[0, K.EV_TIME] == pytest.approx(t_low, abs=1e-8)
        assert close[0, K.EV_REL_VELOCITY] < 1e-3  # grazing approach


def test_free_flight_is_a_parabola_and_tip_vibrates_at_15_um():
    v0, downforce = 0.4, 3.0
    data = {
        "duration_s": 5e-3,
        "downforce_N": downforce,
        "initial": {
            "transducer_z_m": 1e-3,
            "transducer_velocity_m_per_s": v0,
            "free_mass_w_m": 0.0,
            "stem_v_m": 0.0,
        },
        "output": {"output_interval_s": 2e-6},
    }
    _, p, result = run(data)
    assert len(closings(result, 0)) == 0
    t, y = result.samples_t_s, result.samples_y
    accel = p.gravity_m_per_s2 + downforce / p.transducer_mass_kg
    np.testing.assert_allclose(y[:, IZ], 1e-3 + v0 * t - 0.5 * accel * t**2, rtol=0, atol=1e-13)
    vibration = y[:, IX] + downforce / p.modal_stiffness_N_per_m
    assert np.max(np.abs(vibration)) == pytest.approx(15e-6, rel=2e-3)


def test_energy_ledger_closes_on_the_drill_scene():
    _, _, result = run({"duration_s": 0.02, "downforce_N": 9.0})
    balance = result.energy_balance()
    assert result.counters["events"] > 100
    assert balance["closure_relative"] < 1e-10
    for key in (
        "modal_damping_loss_J",
        "contact_tip_ball_loss_J",
        "contact_ball_stem_loss_J",
        "contact_stem_rock_loss_J",
        "electrical_input_J",
    ):
        assert balance[key] > 0.0


def test_bouncing_ball_comes_to_rest_in_finitely_many_impacts():
    """A ball dropped 1 mm onto a resting stem (Zeno for rigid contact) ends in persistent contact."""
    data = {
        "duration_s": 0.3,
        "drive": {"voltage_amplitude_V": 0.0},
        "initial": {"vibration": "rest", "transducer_z_m": 0.5, "free_mass_w_m": 1e-3, "stem_v_m": 0.0},
        "output": {"output_interval_s": 1e-4},
    }
    start = time.perf_counter()
    _, p, result = run(data)
    assert time.perf_counter() - start < 20.0
    n_impacts = len(closings(result, 1))
    e = p.contacts[1].restitution
    # geometric series of rebound speeds down to the speed at which gravity keeps the layer loaded
    assert 5 < n_impacts < 4 * math.log(1e-6) / math.log(e)
    assert result.final_mode & 0b010 and result.final_mode & 0b100
    static = p.free_mass_kg * p.gravity_m_per_s2 / p.contacts[1].stiffness_N_per_m
    assert result.final_y[ID2] == pytest.approx(static, rel=1e-3)
    assert result.energy_balance()["closure_relative"] < 1e-10


def test_ball_chattering_under_a_weakly_vibrating_tip_finishes():
    """1 um tip amplitude against a 9 N squeeze: the ball chatters with sub-micron separations."""
    data = {
        "duration_s": 0.01,
        "downforce_N": 9.0,
        "drive": {"tip_amplitude_m": 1e-6},
        "initial": {"transducer_z_m": 0.0, "free_mass_w_m": 0.0, "stem_v_m": 0.0},
        "output": {"output_interval_s": 1e-5},
    }
    start = time.perf_counter()
    _, p, result = run(data)
    assert time.perf_counter() - start < 20.0
    cycles = data["duration_s"] * p.drive_frequency_Hz
    assert result.counters["events"] < 8 * cycles
    assert result.energy_balance()["closure_relative"] < 1e-10
    # no contact pulls: recorded forces are never below round-off
    forces = result.contact_forces_N()
    assert forces.min() > -1e-6
    assert np.all(np.isfinite(result.samples_y[:, IW]))
