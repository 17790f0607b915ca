"""Wedge-wave stator builder and case: tagged groups, MPI partition equals serial, modes.csv."""

import csv
import json

import pytest
from conftest import CASES

COARSE = ["--set", "geometry.parameters.mesh_size_m=0.0025", "--set", "geometry.parameters.tip_mesh_size_m=0.0012"]


def test_stator_groups_and_contact_band():
    from mpi4py import MPI

    from geometry.stator import StatorParameters, build_stator

    params = StatorParameters(mesh_size_m=0.003, tip_mesh_size_m=0.0015)
    md = build_stator(MPI.COMM_SELF, params, "3d")
    assert set(md.cell_names) == {"base", "tube", "wedge"}
    expected = {"inner", "contact", "tip", "bottom", "sensor", *(f"{p}{k}" for p in "AB" for k in range(1, 5))}
    assert set(md.facet_names) == expected
    x = md.mesh.geometry.x
    r_c, z_c = params.contact_point()
    facets = md.facet_tags.indices[md.facet_tags.values == md.facet_names["contact"]]
    md.mesh.topology.create_connectivity(2, 0)
    vertices = {v for f in facets for v in md.mesh.topology.connectivity(2, 0).links(f)}
    z = x[list(vertices), 2]
    assert abs(z.min() - (z_c - 0.5 * params.contact_band_m)) < 1e-9
    assert abs(z.max() - (z_c + 0.5 * params.contact_band_m)) < 1e-9


def test_stator_modal_two_ranks_equal_serial(cli, tmp_path):
    args = ["run", CASES / "wwusm-stator.toml", "--set", 'analyses=["modal"]', "--set", "output.fields=false",
            *COARSE]
    serial = cli(*args, "--out", tmp_path / "s")
    parallel = cli(*args, "--out", tmp_path / "p", mpi=2)
    assert serial.returncode == 0 and parallel.returncode == 0, serial.stderr + parallel.stderr
    s = json.loads((tmp_path / "s" / "summary.json").read_text())["results"]["modal"]
    p = json.loads((tmp_path / "p" / "summary.json").read_text())["results"]["modal"]
    assert (s["working_m"], s["working_n"]) == (p["working_m"], p["working_n"]) == (1, 4)
    for ms, mp in zip(s["modes"], p["modes"]):
        assert mp["resonance_Hz"] == pytest.approx(ms["resonance_Hz"], rel=1e-6)
        assert (mp["m"], mp["n"], mp["component"]) == (ms["m"], ms["n"], ms["component"])
    rows = list(csv.DictReader(open(tmp_path / "s" / "modes.csv")))
    assert [int(r["n"]) for r in rows] == [m["n"] for m in s["modes"]]
    assert float(rows[s["working_mode_index"]]["resonance_Hz"]) == pytest.approx(s["working_resonance_Hz"],
                                                                                 rel=1e-5)
    assert rows[s["working_mode_index"]]["working"] == "1"
