"""Thin-ring in-plane bending (n = 2, 3, 4) of the 3D ring built by the stator's revolve
construction, against w^2 = E I n^2 (n^2-1)^2 / (rho A R^4 (n^2+1)); mode identification must
find the orders from the Fourier analysis round the ring."""

import math

import pytest

from app.materials import LIBRARY

CASE = "validation/ring-inplane-3d.toml"
R, T, H = 0.02, 0.0005, 0.001


def closed_form_Hz(n: int) -> float:
    steel = LIBRARY["stainless-steel"]
    inertia, area = H * T**3 / 12, H * T
    omega2 = steel.young_Pa * inertia * n**2 * (n**2 - 1) ** 2 / (steel.density_kg_per_m3 * area * R**4 * (n**2 + 1))
    return math.sqrt(omega2) / (2 * math.pi)


@pytest.mark.mpi
def test_ring_inplane_bending_against_closed_form(shared_tmp):
    from conftest import run_case_quiet

    modal = run_case_quiet(CASE, shared_tmp, "output.fields=false", "output.plots=false")["results"]["modal"]
    inplane = {}
    for mode in modal["modes"]:
        if mode["component"] == "r":
            inplane.setdefault(mode["n"], []).append(mode)
    for n in (2, 3, 4):
        pair = inplane[n]
        assert len(pair) == 2, f"n = {n}: expected a degenerate pair, got {len(pair)}"
        f_fe = 0.5 * (pair[0]["resonance_Hz"] + pair[1]["resonance_Hz"])
        # The thin-ring formula leaves out shear and rotary inertia: Timoshenko's terms lower f by
        # ~ (k r_g)^2 (1 + E / (kappa G)) / 2 = 0.17 (n T / R)^2 (k = n / R, r_g^2 = T^2 / 12). Measured
        # at the case's 0.6 mm: +5.5e-5, -3.3e-4, -8.8e-4 for n = 2, 3, 4 (at 0.9 / 0.45 mm: -7.6e-4 /
        # -1.03e-3 for n = 4: the one-element-thick P2 mesh is still a little stiff). Bound 0.3 (n T / R)^2.
        assert f_fe == pytest.approx(closed_form_Hz(n), rel=0.3 * (n * T / R) ** 2)
        # the partners find each other and their split is small (an axisymmetric body)
        assert abs(pair[0]["partner_split_Hz"]) < 2e-3 * f_fe
