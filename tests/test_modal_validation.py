"""Modal analysis against IEEE Std 176 closed forms, mesh convergence and axisymmetric vs 3D."""

import math

import pytest
from ieee176 import bar_33, disc_radial, observed_order, ring_hoop, strip_plane_strain_antiresonance

from app.materials import LIBRARY

PZT4 = LIBRARY["PZT-4"]
C, E, EPS = PZT4.tensors()


def _modal(shared_tmp, case, *overrides):
    from conftest import run_case_quiet

    return run_case_quiet(case, shared_tmp, 'analyses=["modal"]', "output.fields=false", "output.plots=false",
                          *overrides)["results"]["modal"]


@pytest.mark.mpi
def test_pzt4_bar_resonance_and_antiresonance_within_half_percent(shared_tmp):
    f_r, f_a, k33 = bar_33(C, E, EPS, PZT4.density_kg_per_m3, 0.02)
    modal = _modal(shared_tmp, "validation/pzt4-bar-axisymmetric.toml")
    assert modal["working_resonance_Hz"] == pytest.approx(f_r, rel=5e-3)
    assert modal["working_antiresonance_Hz"] == pytest.approx(f_a, rel=5e-3)
    k_eff_closed = math.sqrt(1 - (f_r / f_a) ** 2)
    assert modal["working_k_eff"] == pytest.approx(k_eff_closed, rel=5e-3)
    # IEEE 176 inverted: k33 recovered from the FE frequency pair
    fr_fe, fa_fe = modal["working_resonance_Hz"], modal["working_antiresonance_Hz"]
    k33_fe = math.sqrt((math.pi / 2) * (fr_fe / fa_fe) * math.tan((math.pi / 2) * (fa_fe - fr_fe) / fa_fe))
    assert k33_fe == pytest.approx(k33, rel=5e-3)


def test_bar_convergence_under_refinement(shared_tmp):
    """Error against a Richardson-extrapolated limit shrinks at the P2 rate (order ~4 for eigenvalues)."""
    freqs, hs = [], []
    for n in (4, 8, 16):
        modal = _modal(shared_tmp, "validation/pzt4-bar-axisymmetric.toml", f"geometry.parameters.axial_divisions={n}",
                       "geometry.parameters.lateral_divisions=1", "geometry.degree=2")
        freqs.append(modal["working_antiresonance_Hz"])
        hs.append(1.0 / n)
    reference = _modal(shared_tmp, "validation/pzt4-bar-axisymmetric.toml", "geometry.parameters.axial_divisions=64",
                       "geometry.parameters.lateral_divisions=1", "geometry.degree=2")["working_antiresonance_Hz"]
    errors = [abs(f - reference) for f in freqs]
    assert errors[0] > errors[1] > errors[2]
    assert observed_order(hs, errors) > 3.0


def test_axisymmetric_and_3d_bar_agree(shared_tmp):
    axi = _modal(shared_tmp, "validation/pzt4-bar-axisymmetric.toml")
    solid = _modal(shared_tmp, "validation/pzt4-bar-3d.toml")
    # round vs square section of equal width: lateral inertia differs slightly
    assert solid["working_resonance_Hz"] == pytest.approx(axi["working_resonance_Hz"], rel=2e-3)
    assert solid["working_antiresonance_Hz"] == pytest.approx(axi["working_antiresonance_Hz"], rel=2e-3)


def test_disc_radial_mode_against_closed_form(shared_tmp):
    radius = 0.01
    f_closed = disc_radial(C, E, EPS, PZT4.density_kg_per_m3, radius)
    modal = _modal(shared_tmp, "validation/pzt4-disc.toml")
    assert modal["working_resonance_Hz"] == pytest.approx(f_closed, rel=1e-2)


@pytest.mark.parametrize("case", ["validation/pzt4-ring-axisymmetric.toml", "validation/pzt4-ring-3d.toml"])
def test_radially_poled_ring_against_closed_form(shared_tmp, case):
    """Radial poling: constant rotation in axisymmetric, position-dependent UFL rotation in 3D."""
    f_r, f_a = ring_hoop(C, E, EPS, PZT4.density_kg_per_m3, 0.01)
    modal = _modal(shared_tmp, case)
    assert modal["working_resonance_Hz"] == pytest.approx(f_r, rel=3e-3)
    assert modal["working_antiresonance_Hz"] == pytest.approx(f_a, rel=3e-3)


def test_plane_strain_strip_against_closed_form(shared_tmp):
    f_a = strip_plane_strain_antiresonance(C, E, EPS, PZT4.density_kg_per_m3, 0.02)
    modal = _modal(shared_tmp, "validation/pzt4-strip-plane-strain.toml")
    assert modal["working_antiresonance_Hz"] == pytest.approx(f_a, rel=3e-3)
