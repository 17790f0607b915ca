"""Two-phase harmonic drive of the wedge-wave stator (coarse mesh): superposition of the A and B
phases to solver tolerance, reversal of the wave when B's phase is flipped, the travelling-wave
quality at F(1,4), and the sensor (floating electrode) voltage.

The stator tests are marked slow (~4 min on the shared 2-core machine: 7 block-LU solves of the
2x2 real system). Measured min/max of the normal amplitude at the pair centre: 0.79 (this coarse
mesh) and 0.80 (the case's 1.2 mm mesh), below the issue's 0.9: the n = 4 pair's 9-15 Hz split
against the 72 Hz half-bandwidth leaves a ~10 % backward n = 4 component (docs/motor-stator.md).
The bound below guards that state against regressions; it is not the issue's target."""

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
