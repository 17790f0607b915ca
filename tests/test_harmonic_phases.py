"""Two-phase harmonic drive of the wedge-wave stator (coarse mesh): superposition of the A and B
phases to solver tolerance, reversal of the wave when B's phase is flipped, the travelling-wave
quality at F(1,4), and the sensor (floating electrode) voltage.

The stator tests are marked slow (~1.5 min on the coarse mesh: 9 block-LU solves of the 2x2 real
system; the case-mesh test ~2 min and ~6 GB). With the nominal drive (B 200 V at exactly 90 deg) min/max of the normal
amplitude is 0.79 on this mesh: the pair split and the single phases' spatial offset leave a
backward n = 4 part of ~12 % (docs/motor-stator.md, diagnosis). The case balances B
(harmonic.wave.balance = "B", as a two-phase driver does) and the issue's >= 0.9 is asserted for
that drive; the nominal drive keeps a regression bound."""

import math

import numpy as np
import pytest
from conftest import CASES
from mpi4py import MPI

from app.case.schema import load_case

COARSE = ["geometry.parameters.mesh_size_m=0.0025", "geometry.parameters.tip_mesh_size_m=0.0012"]


@pytest.fixture(scope="module")
def stator():
    from app.fe.model import build_model
    from app.fe.operators import add_damping, assemble_operators
    from app.modal import run_modal

    case = load_case(CASES / "wwusm-stator.toml", COARSE)
    model = build_model(case, MPI.COMM_WORLD)
    ops = assemble_operators(model)
    modal = run_modal(model, ops)
    add_damping(ops, model, modal.working_mode.frequency_Hz)
    yield model, ops, modal
    ops.destroy()


def _solve(stator, phasors, frequency_Hz=None):
    from app.harmonic import HarmonicSolver, wave_measures
    from app.runner import pair_centre_Hz

    model, ops, modal = stator
    f = frequency_Hz or pair_centre_Hz(modal)
    solver = HarmonicSolver(model, ops, 200.0, prefix="test_phases_", phasors=phasors)
    try:
        point = solver.solve(f)
        x_re, x_im = (v.copy() for v in solver.full_solution())
        wave = wave_measures(model, solver, model.case.harmonic.wave, f)
    finally:
        solver.destroy()
    return point, x_re, x_im, wave


@pytest.mark.slow
@pytest.mark.mpi
def test_working_mode_is_the_n4_pair(stator):
    _, _, modal = stator
    order = modal.orders[modal.working]
    assert (order.m, order.n) == (1, 4)
    partner = modal.orders[order.partner]
    assert (partner.m, partner.n) == (1, 4)
    # four-fold electrodes keep the pair nearly degenerate
    assert abs(order.split_Hz) < 2e-3 * modal.working_mode.frequency_Hz


@pytest.mark.slow
@pytest.mark.mpi
def test_phases_superpose(stator):
    a = _solve(stator, {"A": 200.0 + 0j, "B": 0j})
    b = _solve(stator, {"A": 0j, "B": 200j})
    ab = _solve(stator, {"A": 200.0 + 0j, "B": 200j})
    for k in (1, 2):
        total = a[k].copy()
        total.axpy(1.0, b[k])
        total.axpy(-1.0, ab[k])
        assert total.norm() < 1e-9 * ab[k].norm()
    sensor = ab[0].floating_voltage_V["sensor"]
    assert abs(a[0].floating_voltage_V["sensor"] + b[0].floating_voltage_V["sensor"] - sensor) < 1e-9 * abs(sensor)
    assert abs(sensor) > 0
    for name in ("A", "B"):
        q = ab[0].electrode_charge_C[name]
        assert abs(a[0].electrode_charge_C[name] + b[0].electrode_charge_C[name] - q) < 1e-9 * abs(q)


@pytest.mark.slow
@pytest.mark.mpi
def test_both_phases_travel_and_flipping_b_reverses(stator):
    forward = _solve(stator, {"A": 200.0 + 0j, "B": 200j})[3]
    backward = _solve(stator, {"A": 200.0 + 0j, "B": -200j})[3]
    assert forward["travelling_wave_ratio"] >= 0.75
    assert backward["travelling_wave_ratio"] >= 0.75
    assert {forward["direction"], backward["direction"]} == {"+theta", "-theta"}
    assert forward["forward_fraction"] > 0.85 or forward["forward_fraction"] < 0.15
    # a travelling wave: the contact point's tangential and normal motions are in quadrature
    assert abs(abs(forward["ellipse_phase_deg"]) - 90.0) < 15.0
    assert forward["wave_speed_m_per_s"] == pytest.approx(
        2 * math.pi * forward["frequency_Hz"] * 0.01294 / 4, rel=1e-12)


@pytest.mark.slow
@pytest.mark.mpi
def test_balanced_two_phase_drive_travels_with_ratio_09(stator):
    """Both phases driven, B trimmed by the case's balance: min/max >= 0.9 (issue 10) at the F(1,4)
    pair centre; the trim nulls the backward n = 4 part to solver precision and stays a trim (the
    driver changes B by less than 30 deg and 20 % from the nominal 90 deg, 200 V)."""
    from app.harmonic import HarmonicSolver, balanced_wave
    from app.runner import pair_centre_Hz

    model, ops, modal = stator
    cfg = model.case.harmonic.wave
    assert cfg.balance == "B"
    f = pair_centre_Hz(modal)
    solver = HarmonicSolver(model, ops, 200.0, prefix="test_balance_")
    try:
        point, wave = balanced_wave(model, solver, cfg, f)
    finally:
        solver.destroy()
    assert wave["travelling_wave_ratio"] >= 0.9
    assert wave["nominal"]["travelling_wave_ratio"] < wave["travelling_wave_ratio"]
    orders = wave["orders"]
    forward, backward = orders["towards_plus_theta_m"][4], orders["towards_minus_theta_m"][4]
    assert min(forward, backward) < 1e-6 * max(forward, backward)
    balance = wave["balance"]
    assert balance["electrode"] == "B" and balance["nominal_phase_deg"] == pytest.approx(90.0)
    assert abs(balance["phase_deg"] - 90.0) < 30.0
    assert abs(balance["amplitude_V"] / 200.0 - 1.0) < 0.2
    # the other orders (n = 0 breathing, n = 8, ...) stay below 2 % of the wave: 1 - ratio is theirs
    others = [a + b for n, a, b in zip(orders["n"], orders["towards_plus_theta_m"], orders["towards_minus_theta_m"])
              if n != 4]
    assert sum(others) < 0.02 * max(forward, backward)
    assert abs(point.floating_voltage_V["sensor"]) > 0


@pytest.mark.slow
def test_guarded_layout_travels_at_the_case_mesh_without_trim():
    """The layout fix alone, at the case's own mesh (1.2 mm, where the mesh's own asymmetry splits the
    pair by only ~2 Hz; ~3 min, ~4 GB): with the grounded guards and the quadrature sensors the F(1,4)
    pair stays within a few Hz of degenerate, so B at exactly 200 V, 90 deg gives min/max >= 0.9 at the
    pair centre. (With the bare-wall layout this mesh gives 13.6 Hz and 0.81; docs/motor-stator.md.)"""
    from app.fe.model import build_model
    from app.fe.operators import add_damping, assemble_operators
    from app.harmonic import HarmonicSolver, wave_measures
    from app.modal import run_modal
    from app.runner import pair_centre_Hz

    case = load_case(CASES / "wwusm-stator.toml")
    model = build_model(case, MPI.COMM_WORLD)
    ops = assemble_operators(model)
    try:
        modal = run_modal(model, ops)
        order = modal.orders[modal.working]
        assert (order.m, order.n) == (1, 4)
        # the two-mode estimate of the backward part, split / (2 zeta f), stays below the 5 % that 0.9 allows
        assert abs(order.split_Hz) < 0.05 * 2 * 0.002 * modal.working_mode.frequency_Hz
        add_damping(ops, model, modal.working_mode.frequency_Hz)
        f = pair_centre_Hz(modal)
        solver = HarmonicSolver(model, ops, 200.0, prefix="test_nominal_", phasors={"A": 200.0 + 0j, "B": 200j})
        try:
            solver.solve(f)
            wave = wave_measures(model, solver, case.harmonic.wave, f)
        finally:
            solver.destroy()
    finally:
        ops.destroy()
    assert wave["travelling_wave_ratio"] >= 0.9


@pytest.mark.slow
@pytest.mark.mpi
def test_one_phase_is_a_standing_wave(stator):
    wave = _solve(stator, {"A": 200.0 + 0j, "B": 0j})[3]
    assert wave["travelling_wave_ratio"] < 0.5


def test_fourier_identification_of_a_synthetic_field():
    """n and m from a prescribed u_r = cos(4 theta) g(z): g without a sign change (m = 1) and with one
    (m = 2); u_z = sin(3 theta) is order 3 with component z."""
    from app.modeid import axial_order, circumferential_order, cylindrical

    theta = 2 * np.pi * np.arange(64) / 64
    z = np.linspace(0.0, 1.0, 20)
    assert axial_order(np.cos(4 * theta)[:, None] * (1 + z)[None, :], 4) == 1
    assert axial_order(np.cos(4 * theta)[:, None] * (z - 0.4)[None, :], 4) == 2
    u_xyz = np.column_stack([np.cos(4 * theta) * np.cos(theta), np.cos(4 * theta) * np.sin(theta), 0 * theta])
    assert circumferential_order(cylindrical(u_xyz, theta))[:2] == (4, "r")
    u_z = np.column_stack([0 * theta, 0 * theta, np.sin(3 * theta)])
    assert circumferential_order(u_z)[:2] == (3, "z")


def test_balance_factor_nulls_the_backward_part_of_a_split_pair():
    """Two standing n = 4 responses of a split pair (B's leads A's by 7 deg in time and sits 1.6 deg
    off its quarter wavelength), plus an n = 8 remainder: the balance factor removes the -theta part
    exactly, so min/max rises to the level the n = 8 part allows; the spectrum splits the orders."""
    from app.modeid import balance_factor, order_spectrum, travelling_parts

    theta = 2 * np.pi * np.arange(64) / 64
    w_a = np.cos(4 * theta) + 0.01 * np.cos(8 * theta)
    w_b = 1.05j * np.exp(1j * math.radians(7.0)) * np.cos(4 * (theta - math.radians(22.5 + 1.6)))
    nominal = np.abs(w_a + w_b)
    assert nominal.min() / nominal.max() < 0.85
    s = balance_factor(w_a, w_b, 4)
    balanced = w_a + s * w_b
    plus, minus = travelling_parts(balanced, 4)
    assert abs(plus) < 1e-12 * abs(minus)  # w_a + w_b travels towards -theta: the +theta part goes
    amp = np.abs(balanced)
    # |w| stays within |minus| -+ the n = 8 part's peak 0.01
    assert amp.min() / amp.max() >= (abs(minus) - 0.01) / (abs(minus) + 0.01) - 1e-12
    assert amp.min() / amp.max() > 0.97
    spectrum = order_spectrum(balanced, 16)
    assert spectrum["n"] == list(range(17))
    assert spectrum["towards_plus_theta_m"][8] == pytest.approx(0.005, rel=1e-9)
    assert spectrum["towards_minus_theta_m"][8] == pytest.approx(0.005, rel=1e-9)
    assert spectrum["towards_minus_theta_m"][4] == pytest.approx(abs(minus), rel=1e-12)
