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


def test_guarded_layout_tiles_the_wall_without_touching_strips():
    """The case's electrode layout: A, B, two quadrature sensors and grounded guards on a 22.5 deg pitch,
    every outer electrode separated from the others by a bare slit (no shared vertex, so no shared
    potential DOF), the guards where no strip is."""
    from mpi4py import MPI

    from geometry.stator import StatorParameters, build_stator

    layout = dict(strip_width_deg=20.5, guard_width_deg=20.5, sensor_width_deg=20.5, sensor_centre_deg=45.0,
                  sensor2_centre_deg=67.5)
    params = StatorParameters(mesh_size_m=0.003, tip_mesh_size_m=0.0015, **layout)
    centres = sorted(round(0.5 * (lo + hi) % 360.0, 6) for lo, hi in params.guards())
    assert centres == [135.0, 157.5, 225.0, 247.5, 315.0, 337.5]
    md = build_stator(MPI.COMM_SELF, params, "3d")
    outer = ["guard", "sensor", "sensor2", *(f"{p}{k}" for p in "AB" for k in range(1, 5))]
    assert set(outer) <= set(md.facet_names)
    md.mesh.topology.create_connectivity(2, 0)
    f2v = md.mesh.topology.connectivity(2, 0)
    vertices = {}
    for name in outer:
        facets = md.facet_tags.indices[md.facet_tags.values == md.facet_names[name]]
        vertices[name] = {v for f in facets for v in f2v.links(f)}
        assert vertices[name]
    for i, a in enumerate(outer):
        for b in outer[i + 1:]:
            assert not vertices[a] & vertices[b], f"{a} touches {b}"


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
