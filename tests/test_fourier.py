"""The Fourier-harmonic model (geometry.model = "fourier"): a body of revolution meshed in (r, z) whose
fields are one circumferential order n, exactly in theta (forms/kinematics.py, docs/fourier.md).

References: the thin-ring closed form for in-plane bending (and its thickness correction, which must shrink
as (t/R)^2); the axisymmetric model (n = 0 is the axisymmetric model plus torsion, on the same mesh); the 3D
model of the same body, swept from the same profile mesh (tests/test_stator_mesh.py)."""

import math

import pytest
from conftest import CASES, run_case_quiet, run_cli

from app.materials import LIBRARY

RING = "validation/ring-inplane-fourier.toml"
R, T, H = 0.02, 0.0005, 0.001


def closed_form_Hz(n: int, t: float = T) -> float:
    steel = LIBRARY["stainless-steel"]
    inertia, area = H * t**3 / 12, H * t
    omega2 = steel.young_Pa * inertia * n**2 * (n**2 - 1) ** 2 / (steel.density_kg_per_m3 * area * R**4 * (n**2 + 1))
    return math.sqrt(omega2) / (2 * math.pi)


def inplane_Hz(out, n: int, t: float = T) -> float:
    modal = run_case_quiet(RING, out, f"geometry.circumferential_order={n}",
                           f"geometry.parameters.radial_thickness_m={t}", "output.fields=false",
                           "output.plots=false")["results"]["modal"]
    inplane = [m for m in modal["modes"] if m["component"] == "r"]
    assert inplane, "no in-plane (radial) mode found"
    assert all(m["n"] == n and m["partner_split_Hz"] == 0.0 for m in modal["modes"])
    return min(m["resonance_Hz"] for m in inplane)


def test_thin_ring_inplane_bending_against_closed_form(tmp_path):
    """n = 2, 3, 4 within 0.2 % of the thin-ring formula, and the residual is the ring's thickness (shear and
    rotary inertia of the section, of order (n t / R)^2): it grows with n, and halving t/R divides it by more
    than 3 (measured: -0.143 % at t/R = 1/40, -0.022 % at 1/80, +0.018 % at 1/160 for n = 4; the mesh error is
    below 1e-7 at these sizes: 1148 and 15444 DOFs agree to 2.5e-8)."""
    errors = {}
    for n in (2, 3, 4):
        f = inplane_Hz(tmp_path / f"n{n}", n)
        errors[n] = f / closed_form_Hz(n) - 1
        assert abs(errors[n]) < 2e-3, f"n = {n}: {f:.2f} Hz against {closed_form_Hz(n):.2f} Hz"
    # the thick-ring correction grows with n (shear and rotary inertia of the section)
    assert abs(errors[2]) < abs(errors[3]) < abs(errors[4])
    thin = inplane_Hz(tmp_path / "thin", 4, T / 2) / closed_form_Hz(4, T / 2) - 1
    assert abs(thin) < abs(errors[4]) / 3 and abs(thin) < 5e-4, (errors[4], thin)


def test_order_zero_is_the_axisymmetric_model(tmp_path):
    """n = 0 on the mesh of the axisymmetric PZT ring: the same piezoelectric modes (resonance and
    antiresonance of the breathing mode), plus torsion, which the axisymmetric model lacks."""
    case = "validation/pzt4-ring-axisymmetric.toml"
    axi = run_case_quiet(case, tmp_path / "axi", "output.fields=false", "output.plots=false")["results"]["modal"]
    four = run_case_quiet(case, tmp_path / "four", 'geometry.model="fourier"', "geometry.circumferential_order=0",
                          "modal.n_modes=6", "output.fields=false", "output.plots=false")["results"]["modal"]
    f_r, f_a = axi["working_resonance_Hz"], axi["working_antiresonance_Hz"]
    assert four["working_resonance_Hz"] == pytest.approx(f_r, rel=1e-9)
    assert four["working_antiresonance_Hz"] == pytest.approx(f_a, rel=1e-9)
    assert four["working_k_eff"] == pytest.approx(axi["working_k_eff"], rel=1e-6)


def test_open_circuit_is_short_circuit_for_orders_above_zero(tmp_path):
    """An electrode round the whole circumference is one equipotential: it has no cos n theta part, so for
    n >= 1 a floating electrode is a grounded one (the 3D ring's n >= 1 modes have no coupling either)."""
    case = "validation/pzt4-ring-axisymmetric.toml"
    four = run_case_quiet(case, tmp_path, 'geometry.model="fourier"', "geometry.circumferential_order=2",
                          "modal.target_frequency_Hz=5000.0", "output.fields=false",
                          "output.plots=false")["results"]["modal"]
    assert four["working_antiresonance_Hz"] == pytest.approx(four["working_resonance_Hz"], rel=1e-12)


@pytest.mark.parametrize("overrides, key", [
    (['geometry.model="fourier"'], "geometry.circumferential_order"),
    (["geometry.circumferential_order=4"], "geometry.circumferential_order"),
    (['geometry.model="fourier"', "geometry.circumferential_order=4", 'analyses=["modal", "harmonic"]',
      "harmonic.n_points=3"],
     "analyses[1]"),
    (['geometry.model="fourier"', "geometry.circumferential_order=4", 'regions[0].poling="+x"'],
     "regions[0].poling"),
])
def test_bad_fourier_input_is_one_line(overrides, key, tmp_path):
    args = [a for o in overrides for a in ("--set", o)]
    result = run_cli("validate", CASES / "validation/pzt4-ring-axisymmetric.toml", *args)
    assert result.returncode == 2, result.stderr
    assert key in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
