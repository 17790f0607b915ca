"""The stator's drive levers and its modal force F_m (app/modal.py contact_force, docs/motor-stator.md).

References: the harmonic steady state (F_m = 2 zeta k_m W: the modal force referred to the contact must
reproduce the free normal amplitude the harmonic analysis gives at the pair's resonance); the Fourier content
of the segment pattern (A+ and A- segments half a wavelength apart, driven in antiphase, double the n = 4 drive
and cancel n = 0 and n = 8); the field per volt of a multilayer wall (the layer count)."""

import math

import numpy as np
import pytest
from conftest import ROOT

# the stator before issue 24 (one layer, A/B segments and guards), on its swept mesh: the levers act on it
CASE = ROOT / "bench" / "cases" / "wwusm-stator-two-phase.toml"
COARSE = ["geometry.parameters.mesh_method=swept", "geometry.parameters.mesh_size_m=0.004",
          "geometry.parameters.tip_mesh_size_m=0.002",
          "geometry.parameters.arc_mesh_size_m=0.002", "output.fields=false", "output.plots=false",
          # the coarse faceted faces sag: sample further inside
          "modal.identify.line_radius_m=0.0133", "modal.identify.circle_radius_m=0.01305",
          "modal.contact_force.circle_radius_m=0.01305", "harmonic.wave.circle_radius_m=0.01305"]
ALL_SEGMENT = [
    "geometry.parameters.negative_phase_segments=true", "geometry.parameters.sensor_height_m=0.001",
    'electrodes.common.facets=["inner"]',
    'electrodes.Am={facets=["Am1", "Am2", "Am3", "Am4"], kind="voltage", amplitude_V=200.0, phase_deg=180.0}',
    'electrodes.Bm={facets=["Bm1", "Bm2", "Bm3", "Bm4"], kind="voltage", amplitude_V=200.0, phase_deg=270.0}']
MULTILAYER = ["geometry.parameters.tube_layers=3",
              'regions=[{cells="base", material="steel"}, {cells="tube", material="pzt4", poling="radial"}, '
              '{cells="tube_reversed", material="pzt4", poling="-radial"}, {cells="wedge", material="steel"}]']


def model_and_modes(overrides):
    from app.case.schema import load_case
    from app.fe.model import build_model
    from app.fe.operators import add_damping, assemble_operators
    from app.modal import run_modal

    case = load_case(CASE, COARSE + overrides)
    model = build_model(case)
    ops = assemble_operators(model)
    modal = run_modal(model, ops)
    add_damping(ops, model, modal.working_mode.frequency_Hz)
    return case, model, ops, modal


def normal_wave(model, ops, phasors, frequency_Hz):
    from app.harmonic import HarmonicSolver, circle_phasors
    from app.modeid import normal_component

    cfg = model.case.harmonic.wave
    solver = HarmonicSolver(model, ops, 200.0, phasors=phasors)
    try:
        solver.solve(frequency_Hz)
        u, _ = circle_phasors(model, solver, cfg)
        return normal_component(u, tuple(cfg.normal_rz))
    finally:
        solver.destroy()


def centre_Hz(modal):
    partner = modal.orders[modal.working].partner
    return 0.5 * (modal.working_mode.frequency_Hz + modal.short[partner].frequency_Hz)


@pytest.mark.slow
def test_modal_force_gives_the_harmonic_amplitude():
    """F_m from the modes' electrode charges, and 2 zeta k_m W with W the free normal amplitude of the
    harmonic steady state (nominal two-phase drive at the pair's centre): within 3 % (the other modes'
    share and the pair's split, which the single-mode relation leaves out)."""
    _, model, ops, modal = model_and_modes([])
    cf = modal.contact_force
    w = normal_wave(model, ops, None, centre_Hz(modal))
    W = np.abs(w).mean()
    assert 2 * cf["damping_ratio"] * cf["modal_stiffness_N_per_m"] * W == pytest.approx(cf["modal_force_N"], rel=0.03)
    assert cf["free_normal_amplitude_m"] == pytest.approx(W, rel=0.03)
    # N / F_m as the summary defines it: N = P / sin 15 deg
    assert cf["preloads"][1]["normal_force_N"] == pytest.approx(4.116 / math.sin(math.radians(15)), rel=1e-4)
    ops.destroy()


@pytest.mark.slow
def test_all_segment_drive_doubles_order_four_and_cancels_zero_and_eight():
    """One phase: A alone against A with its antiphase A- segments (45 deg, half a wavelength of n = 4, away).
    The n = 4 part of the wave about doubles (1.85 to 2.05: A-1 is 1.3 mm shorter, under a sensor patch),
    the n = 0 and n = 8 parts fall below a tenth of A alone's."""
    from app.modeid import order_spectrum

    _, model, ops, modal = model_and_modes(ALL_SEGMENT)
    f = centre_Hz(modal)

    def parts(phasors):
        spec = order_spectrum(normal_wave(model, ops, phasors, f), 8)
        return {n: spec["towards_plus_theta_m"][n] + spec["towards_minus_theta_m"][n] for n in (0, 4, 8)}

    single = parts({"A": 200.0, "Am": 0j, "B": 0j, "Bm": 0j})
    both = parts({"A": 200.0, "Am": -200.0, "B": 0j, "Bm": 0j})
    assert 1.85 < both[4] / single[4] < 2.05, (single, both)
    assert both[0] < 0.1 * single[0] and both[8] < 0.1 * single[8], (single, both)
    ops.destroy()


@pytest.mark.slow
def test_three_layer_wall_triples_the_modal_force_per_volt():
    """The same stator with its wall cut into three layers (internal electrodes, alternating poling): three
    times the field per volt, so about three times F_m per volt (2.6 to 3.2: the internal electrodes shorten
    and stiffen the wall a little, and the mode changes with it)."""
    one = model_and_modes([])[3].contact_force["modal_force_per_volt_N_per_V"]
    three = model_and_modes(MULTILAYER)[3].contact_force["modal_force_per_volt_N_per_V"]
    assert 2.6 < three / one < 3.2, (one, three)
