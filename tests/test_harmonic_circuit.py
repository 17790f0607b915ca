"""Harmonic sweep vs modal f_r/f_a, the equivalent circuit vs FE, and the drill transducer design."""

import math

import pytest
from conftest import run_case_quiet


@pytest.fixture(scope="module")
def bar_results(tmp_path_factory):
    from mpi4py import MPI

    out = MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp("bar")), root=0)
    return run_case_quiet("validation/pzt4-bar-axisymmetric.toml", out)


@pytest.mark.mpi
def test_admittance_extrema_sit_at_modal_frequencies(bar_results):
    r = bar_results["results"]
    # damping (Q ~ 400) shifts the |Y| extrema by O(1/Q^2) ~ 1e-6
    assert r["harmonic"]["admittance_peak_Hz"] == pytest.approx(r["modal"]["working_resonance_Hz"], rel=2e-5)
    assert r["harmonic"]["admittance_trough_Hz"] == pytest.approx(r["modal"]["working_antiresonance_Hz"], rel=2e-5)


def test_admittance_is_capacitive_off_resonance(bar_results):
    h = bar_results["results"]["harmonic"]
    # below resonance a piezo bar is a capacitor: phase +90 deg
    assert h["admittance_phase_deg"][0] == pytest.approx(90.0, abs=2.0)


def test_equivalent_circuit_reproduces_fe_response(bar_results):
    c = bar_results["results"]["circuit"]
    assert c["admittance_at_peak_circuit_S"] == pytest.approx(c["admittance_at_peak_fe_S"], rel=1e-3)
    assert c["displacement_per_volt_at_peak_circuit_m_per_V"] == pytest.approx(
        c["displacement_per_volt_at_peak_fe_m_per_V"], rel=1e-3)
    # clamped capacitance of a 33 bar lies between eps33^S A/L and the free value
    from app.materials import LIBRARY

    _, _, eps = LIBRARY["PZT-4"].tensors()
    area = math.pi * 0.001**2
    c_clamped = eps[2, 2] * area / 0.02
    assert c_clamped * 0.95 < c["clamped_capacitance_F"] < c_clamped * 1.5


@pytest.mark.mpi
def test_drill_transducer_design(shared_tmp):
    """Drill paper: first longitudinal mode ~20.1 kHz, ~300 g; voltage for a 15 um tip amplitude."""
    s = run_case_quiet("usdc-transducer.toml", shared_tmp, "harmonic.n_points=9", "output.fields=false",
                       "output.plots=false")
    r = s["results"]
    assert r["modal"]["working_resonance_Hz"] == pytest.approx(20100.0, rel=1e-2)
    assert r["mass_kg"] == pytest.approx(0.300, rel=3e-2)
    assert r["harmonic"]["admittance_peak_Hz"] == pytest.approx(r["modal"]["working_resonance_Hz"], rel=1e-4)
    assert r["harmonic"]["admittance_trough_Hz"] == pytest.approx(r["modal"]["working_antiresonance_Hz"], rel=1e-4)
    volts = r["harmonic"]["voltage_for_target_amplitude_V"]
    per_volt = r["harmonic"]["displacement_tip_at_peak_amplitude_m"] / s["case"]["harmonic"]["voltage_V"]
    assert volts * per_volt == pytest.approx(15e-6, rel=1e-9)
    assert 5.0 < volts < 500.0
    circuit = r["circuit"]
    # equivalent circuit consistent with the FE sweep at resonance
    assert circuit["admittance_at_peak_circuit_S"] == pytest.approx(circuit["admittance_at_peak_fe_S"], rel=1e-2)
    # damping from Q_m (steel 1000, PZT 400) and beta = 8e-9 s gives an overall Q between 250 and 1000
    assert 250 < circuit["mechanical_quality_factor"] < 1000


def test_mode_shapes_are_valid_xdmf(tmp_path):
    """XDMF + HDF5 that ParaView reads: one displacement field per mode, each non-zero."""
    import xml.etree.ElementTree as ET

    import h5py
    import numpy as np

    summary = run_case_quiet("validation/pzt4-bar-axisymmetric.toml", tmp_path, 'analyses=["modal"]',
                             "geometry.parameters.axial_divisions=8")
    n_modes = len(summary["results"]["modal"]["modes"])
    tree = ET.parse(tmp_path / "modes_short.xdmf")
    grids = [g for g in tree.iter("Grid") if g.get("GridType") == "Uniform"]
    assert len(grids) == n_modes
    frequencies = [float(g.find("Time").get("Value")) for g in grids]
    assert frequencies == pytest.approx([m["resonance_Hz"] for m in summary["results"]["modal"]["modes"]])
    with h5py.File(tmp_path / "modes_short.h5", "r") as h5:
        vertices = h5["mesh/geometry"].shape[0]
        for k in range(1, n_modes + 1):
            values = np.asarray(h5[f"mode_{k}/displacement"])
            assert values.shape == (vertices, 3) and np.abs(values).max() > 0
            assert h5[f"mode_{k}/potential"].shape == (vertices,)
