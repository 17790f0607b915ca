"""Electrode conditions: a floating electrode (equipotential, zero net charge) gives the 33 bar its
open-circuit antiresonance, against IEEE Std 176 (the stator's floating sensors are checked in a
harmonic solve in tests/test_harmonic_phases.py); MPI partitions give the serial eigenfrequencies."""

import json

import pytest
from conftest import CASES, run_case_quiet

BAR = "validation/pzt4-bar-axisymmetric.toml"


@pytest.mark.mpi
def test_floating_electrode_gives_open_circuit_frequency(shared_tmp):
    """The bar with its driven electrode made floating has no driven electrode left, so its
    short-circuit modal analysis sees the open circuit: the fundamental is IEEE 176's
    f_a = 1 / (2 L sqrt(rho s33^D)), lowered by the rod's lateral inertia (Rayleigh-Love, Poisson's
    ratio nu^D = -s13^D / s33^D of the open circuit: -4.17e-4). Measured -4.19e-4 (mesh error 4e-7 at
    the case's 20 divisions; 10/20/40 divisions converge at order 4): tolerance 1e-5, the next
    term of the rod theory, O((nu k r)^4) ~ 3e-6, with margin. A floating electrode that shorted to
    ground would give f_r (25 % lower). (Leaving the face bare gives f_a too, to 1e-10, in this
    one-dimensional field: the equipotential is checked where it matters, on the stator's sensors.)"""
    from ieee176 import bar_33, rayleigh_love_factor

    from app.materials import LIBRARY
    from forms import voigt

    floating = run_case_quiet(BAR, shared_tmp / "b", 'analyses=["modal"]', "output.fields=false",
                              'electrodes.hot.kind="floating"', 'modal.working_mode="nearest"',
                              "modal.target_frequency_Hz=1e5")
    pzt4 = LIBRARY["PZT-4"]
    c, e, eps = pzt4.tensors()
    _, f_a, _ = bar_33(c, e, eps, pzt4.density_kg_per_m3, 0.02)
    s_d = voigt.open_circuit_compliance(c, e, eps)
    expected = f_a * rayleigh_love_factor(-s_d[0, 2] / s_d[2, 2], 0.001, 0.02)
    assert floating["results"]["modal"]["working_resonance_Hz"] == pytest.approx(expected, rel=1e-5)


def test_mpi_two_ranks_equal_serial(cli, tmp_path):
    args = ["run", CASES / BAR, "--set", 'analyses=["modal"]', "--set", "output.fields=false",
            "--set", "geometry.parameters.axial_divisions=30"]
    serial = cli(*args, "--out", tmp_path / "s")
    parallel = cli(*args, "--out", tmp_path / "p", mpi=2)
    assert serial.returncode == 0 and parallel.returncode == 0, serial.stderr + parallel.stderr
    s = json.loads((tmp_path / "s" / "summary.json").read_text())["results"]["modal"]["modes"]
    p = json.loads((tmp_path / "p" / "summary.json").read_text())["results"]["modal"]["modes"]
    assert len(s) == len(p)
    for ms, mp in zip(s, p):
        assert mp["resonance_Hz"] == pytest.approx(ms["resonance_Hz"], rel=1e-6)
        assert ("antiresonance_Hz" in mp) == ("antiresonance_Hz" in ms)
        if "antiresonance_Hz" in ms:
            assert mp["antiresonance_Hz"] == pytest.approx(ms["antiresonance_Hz"], rel=1e-6)
    # only rank 0 prints: each progress line appears once
    assert parallel.stdout.count("modal: working mode") == 1
