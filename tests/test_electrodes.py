"""Electrode conditions: a floating electrode (equipotential, zero net charge) reproduces the
open-circuit antiresonance; MPI partitions give the serial eigenfrequencies."""

import json

import pytest
from conftest import CASES, run_case_quiet

BAR = "validation/pzt4-bar-axisymmetric.toml"


@pytest.mark.mpi
def test_floating_electrode_gives_open_circuit_frequency(shared_tmp):
    regular = run_case_quiet(BAR, shared_tmp / "a", 'analyses=["modal"]', "output.fields=false")
    floating = run_case_quiet(BAR, shared_tmp / "b", 'analyses=["modal"]', "output.fields=false",
                              'electrodes.hot.kind="floating"', 'modal.working_mode="nearest"',
                              "modal.target_frequency_Hz=1e5")
    f_a = regular["results"]["modal"]["working_antiresonance_Hz"]
    assert floating["results"]["modal"]["working_resonance_Hz"] == pytest.approx(f_a, rel=1e-9)


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
