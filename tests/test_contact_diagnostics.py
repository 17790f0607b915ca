"""The contact's diagnostics in the wave's frame (app/contact/law.py ``accumulate_site``, app/contact/tables.py):
a synthetic travelling wave fed through the one accumulation rule of both tiers, then read as the motor scene reads
it.

The pattern: a ring of 72 sites (area w each) under a wave of 4 wavelengths round the ring travelling towards +theta,
the sites' normal displacement towards the obstacle u = A cos(omega t - 4 theta) (so a site's wave phase is
xi = 4 theta - omega t: 0 at the crest, positive ahead of it), a pressure pulse p = p0 cos^4(xi - delta) where
cos(xi - delta) > 0 (or p0 (1 + cos(xi - delta))^2 / 4), centred delta ahead of the crest, and a slip
s = (v1 cos xi, v2 sin xi) in (e1, e2) while in contact. 36 steps per period: every site's wave phase falls on a
bin centre (the sites sit 20 deg of wave apart and the drive moves 10 deg a step).

References and tolerances:
- the contact's centre from the sites' first harmonics (``contact_centre_rad``) is delta: the rectangle rule over a
  whole period integrates a trigonometric polynomial of degree below the steps per period exactly: delta to 1e-9
  rad for the pulse (1 + cos)^2 / 4 (times exp(i xi): degree 3 < 36); the clipped cos^4 is no polynomial, its
  harmonics above 35 alias into the sum (measured 1.4e-6 rad): delta to 1e-5 rad;
- the wave-frame bins hold p at their centres (round-off, 1e-12 relative: each sample lands on its bin's centre);
  their normal force sums to the sites' mean pressure times area (round-off: the same products summed);
- the friction power splits into its e1 and e2 parts as tau s_k^2 / sqrt(|s|^2 + eps^2) and the slip speeds'
  parts are the means of |s1|, |s2| (both against the same sums done here in numpy, round-off);
- a site's wave phase comes from the previous interval: the first interval fills no bin (exact).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.contact import law
from app.contact.tables import (
    BIN_COLUMNS,
    WAVE_BINS,
    SiteTables,
    contact_centre_rad,
    wave_frame_centre_rad,
    wave_phase_bins_deg,
)

N_SITES, WAVES, STEPS = 72, 4, 36
OMEGA = 2 * math.pi * 36000.0
PERIOD = 2 * math.pi / OMEGA
AREA, P0, A, V1, V2 = 1e-7, 5e6, 1e-6, 0.3, 0.05
MU, FACT, EPS, CAP = 0.5, 1.2, 1e-3, 1e9


def _records():
    theta = 2 * math.pi * np.arange(N_SITES) / N_SITES
    frames = np.zeros((N_SITES, 3, 3))
    frames[:, 0] = [0.0, 0.0, 1.0]                        # n: the obstacle's normal (u towards it is -n.y)
    frames[:, 1] = np.column_stack([-np.sin(theta), np.cos(theta), np.zeros(N_SITES)])
    frames[:, 2] = np.column_stack([np.cos(theta), np.sin(theta), np.zeros(N_SITES)])
    sites = law.Sites(np.zeros((N_SITES * 3, 1)), np.zeros((N_SITES, 3)), np.zeros((N_SITES, 3)), np.zeros(N_SITES),
                      np.full(N_SITES, AREA), np.zeros(N_SITES, np.int64), frames)
    one = np.ones(1)
    contacts = law.Contacts(np.array([law.SURFACE]), np.array([law.CONE]), np.zeros(1, np.int64), np.zeros((1, 3)),
                            one, one, one, one, one, one, MU * one, FACT * one, 0.0 * one, CAP * one, EPS * one)
    return theta, sites, contacts


def _run(delta: float, periods: int, clipped: bool = True):
    """The tables after ``periods`` intervals of one period each, and the pending rows; plus numpy's own sums of
    the friction power and slip parts over the last period."""
    theta, sites, contacts = _records()
    tables = SiteTables([("ring", np.ones(N_SITES, bool))], N_SITES, PERIOD)
    dt = PERIOD / STEPS
    check = np.zeros((N_SITES, 4))
    for n in range(1, periods * STEPS + 1):
        t = n * dt
        wt = OMEGA * t
        xi = WAVES * theta - wt
        u = A * np.cos(wt - WAVES * theta)
        pulse = np.cos(xi - delta) ** 4
        # clipped: a pulse of half the wavelength; else the whole-wavelength (1 + cos)^2 / 4, degree 2
        p = P0 * np.where(np.cos(xi - delta) > 0, pulse, 0.0) if clipped else P0 * (1 + np.cos(xi - delta)) ** 2 / 4
        s1, s2 = V1 * np.cos(xi), V2 * np.sin(xi)
        speed = np.sqrt(s1 ** 2 + s2 ** 2 + 1e-30)
        tau = np.minimum(MU * FACT * p, CAP)     # the law's shear stress: DC = 0, mu_s at every speed
        for i in range(N_SITES):
            law.accumulate_site(i, law.SiteSample(p[i] * AREA, s1[i], s2[i], speed[i], tau[i], u[i], AREA, EPS),
                                law.DriveClock(dt, math.cos(wt), math.sin(wt), wt, math.cos(wt), math.sin(wt)),
                                law.SiteAccumulators(tables.sums, tables.bins, tables.groups, tables.phase))
        if n > (periods - 1) * STEPS:
            slipping = (p > 0) & (speed > EPS)
            reg = np.sqrt(speed ** 2 + EPS ** 2)
            check += dt * slipping[:, None] * np.column_stack([np.abs(s1), np.abs(s2), tau * s1 ** 2 / reg,
                                                               tau * s2 ** 2 / reg])
        if tables.due(t):
            tables.row(t)
    return tables.take(), check / PERIOD


@pytest.mark.parametrize("delta_deg", [23.0, -37.0])
def test_the_contact_centre_is_the_pulses_offset_from_the_crest(delta_deg):
    delta = math.radians(delta_deg)
    rows, _ = _run(delta, 1, clipped=False)
    table = {k.split("_sites_")[1]: v for k, (_, v) in rows.items()}
    centre = contact_centre_rad(np.full(N_SITES, AREA), table["pressure_cos"][-1], table["pressure_sin"][-1],
                                table["normal_displacement_cos"][-1], table["normal_displacement_sin"][-1])
    assert centre == pytest.approx(delta, abs=1e-9)
    rows, _ = _run(delta, 1, clipped=True)
    table = {k.split("_sites_")[1]: v for k, (_, v) in rows.items()}
    centre = contact_centre_rad(np.full(N_SITES, AREA), table["pressure_cos"][-1], table["pressure_sin"][-1],
                                table["normal_displacement_cos"][-1], table["normal_displacement_sin"][-1])
    assert centre == pytest.approx(delta, abs=1e-5)
    # the harmonic's amplitude is A (the displacement's cosine and sine coefficients)
    amplitude = np.hypot(table["normal_displacement_cos"][-1], table["normal_displacement_sin"][-1])
    assert np.allclose(amplitude, A, rtol=1e-12)


def test_the_wave_frame_bins_hold_the_pressure_against_the_wave_phase():
    delta = math.radians(30.0)
    rows, check = _run(delta, 2)
    table = {k.split("_sites_")[1]: v for k, (_, v) in rows.items()}
    frame = table["wave_frame"]
    assert frame.shape == (2, 1, WAVE_BINS, len(BIN_COLUMNS))
    assert not frame[0].any()                       # the first interval: no wave phase yet
    area, force = frame[1, 0, :, 0], frame[1, 0, :, 1]
    # every site spends 1/36 of the period in each bin
    assert np.allclose(area, N_SITES * AREA / WAVE_BINS, rtol=1e-12)
    xi = np.radians(wave_phase_bins_deg())
    expected = P0 * np.where(np.cos(xi - delta) > 1e-12, np.cos(xi - delta) ** 4, 0.0)
    assert np.allclose(force / area, expected, rtol=1e-12, atol=1e-9 * P0)
    # conservation: the bins' normal force is the sites' mean pressure times area
    assert force.sum() == pytest.approx(AREA * table["pressure"][1].sum(), rel=1e-12)
    # the binned centre: the bins at their centres, here exactly the samples
    assert wave_frame_centre_rad(frame[1]) == pytest.approx(delta, abs=1e-9)
    # the contact states add up: closed = stick + slip either way
    closed, stick, positive, negative = (frame[1, 0, :, k] for k in (2, 3, 4, 5))
    assert np.allclose(closed, stick + positive + negative, rtol=1e-12, atol=0)
    assert (positive[xi_in(delta, +1)] > 0).all() and (negative[xi_in(delta, -1)] > 0).all()
    # the slip's parts and the friction power's split
    for k, key in enumerate(("slip_speed_e1", "slip_speed_e2", "friction_power_e1", "friction_power_e2")):
        assert np.allclose(table[key][1], check[:, k], rtol=1e-12, atol=1e-12 * np.abs(check[:, k]).max())
    assert (table["slip_speed_e1"][1] <= table["slip_speed"][1] * (1 + 1e-12)).all()
    assert (table["slip_speed"][1] <= (table["slip_speed_e1"][1] + table["slip_speed_e2"][1]) * (1 + 1e-12)).all()


def xi_in(delta, sign):
    """Bins in contact where the slip along e1 (v1 cos xi) has the given sign."""
    xi = np.radians(wave_phase_bins_deg())
    return (np.cos(xi - delta) > 1e-6) & (np.sign(np.cos(xi)) == sign) & (np.abs(np.cos(xi)) > 1e-6)
