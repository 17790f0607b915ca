"""Every XDMF piezodyn writes opens in meshio (a declared dependency) as well as in ParaView (issue 28: meshio's
TimeSeriesReader refused the transient field file, "Couldn't find the mesh grid"): a drill FE result, the same
scene in the modal tier and a transducer modal result, each read with the expected point and cell data names;
the bodies' companion file moves its triangles as the time series says the bodies move; the series as CSV on
request; one mode numbering and the stated mode-shape amplitude. ParaView's own readers open the same files in
tests/test_paraview.py."""

from __future__ import annotations

import csv
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest
from conftest import run_case_quiet

FE_TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
           "output.plots=false", "transient.end_time_s=1e-4", "transient.output_interval_s=5e-5",
           "output.series_csv=true"]
TRANSDUCER_MODAL = ['analyses=["modal"]', "output.plots=false", "geometry.parameters.mesh_size_m=0.003",
                    "geometry.parameters.ceramic_mesh_size_m=0.002"]


# the default [output] derived fields, units in their names (docs/fields.md)
DEFAULT_DERIVED_NAMES = {"von_mises_Pa", "principal_stress_Pa", "electric_field_V_per_m"}

def check_region_names(cell_data: dict, names: dict) -> None:
    """The region names as meshio reads them: besides the ``region`` tag, one cell array per named region
    (``region: <name>``, 1 exactly in the cells with that tag; app/exports.py region_indicators), the names of
    summary.json ``regions``."""
    assert len(names) >= 2
    assert set(cell_data) == {"region", *(f"region: {name}" for name in names.values())}
    for tag, name in names.items():
        indicator = cell_data[f"region: {name}"][0]
        assert indicator.any()
        np.testing.assert_array_equal(indicator, cell_data["region"][0] == int(tag))


def read_series(path) -> tuple[np.ndarray, list, list[tuple[float, dict, dict]]]:
    """(points, cell blocks, [(time, point_data, cell_data)]) of an XDMF time series, through meshio."""
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k) for k in range(reader.num_steps)]
    return points, cells, frames


@pytest.fixture(scope="module", params=["fe", "modal"])
def drill(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"drill_{request.param}")
    summary = run_case_quiet("usdc-fe.toml", out, *FE_TINY, f'tier="{request.param}"')
    return out, summary


def test_every_transient_xdmf_reads_in_meshio(drill):
    out, summary = drill
    files = sorted(p.name for p in out.glob("*.xdmf"))
    assert files == ["transient_bodies.xdmf", "transient_fields.xdmf"]
    n_outputs = summary["results"]["transient"]["field_outputs"]
    assert n_outputs == 8           # phase-locked: one burst of 8 frames over the first 20.1 kHz period
    points, cells, frames = read_series(out / "transient_fields.xdmf")
    assert len(frames) == n_outputs and cells[0].type == "triangle"
    for _, point_data, cell_data in frames:
        assert set(point_data) == {"displacement", "potential", *DEFAULT_DERIVED_NAMES}
        check_region_names(cell_data, summary["regions"])
        assert point_data["displacement"].shape == (len(points), 3)
    assert max(np.abs(frames[-1][1]["displacement"]).max(), 0) > 1e-7       # the transducer rings

    body_points, body_cells, body_frames = read_series(out / "transient_bodies.xdmf")
    assert [f[0] for f in body_frames] == [f[0] for f in frames]             # the same output times
    (triangles,) = body_cells
    assert triangles.type == "triangle" and len(triangles.data) > 40
    for _, point_data, cell_data in body_frames:
        assert set(point_data) == {"displacement"} and set(cell_data) == {"body", "sector"}


def test_the_bodies_move_as_their_series_says(drill):
    """Each body's drawn vertices are displaced by its reference point's motion in transient.h5 at the output
    times (the ball and the stem only translate here), the fixed rock not at all."""
    out, _ = drill
    points, (triangles,), frames = read_series(out / "transient_bodies.xdmf")
    with h5py.File(out / "transient_fields" / "bodies.h5", "r") as f:
        names = [str(n) for n in f["body"].attrs["names"]]
    with h5py.File(out / "transient.h5", "r") as f:
        time = f["time_s"][:]
        positions = {name: f[f"{name}_position_m"][:] for name in ("ball", "stem")}
    body = frames[0][2]["body"][0]
    moved = 0.0
    for t, point_data, _ in frames:
        row = int(np.argmin(np.abs(time - t)))
        assert t == 0.0 or time[row] == pytest.approx(t, rel=1e-12)     # the series' rows start after t = 0
        u = point_data["displacement"]
        for index, name in enumerate(names):
            vertices = np.unique(triangles.data[body == index])
            expected = np.zeros(3)
            if name != "rock" and t > 0:                # at t = 0 every body is at its start
                start = np.array([0.0, {"ball": -0.00401, "stem": -0.00802}[name]])
                expected[:2] = positions[name][row] - start
                moved = max(moved, abs(expected[1]))
            np.testing.assert_allclose(u[vertices], np.tile(expected, (len(vertices), 1)), rtol=0, atol=1e-15)
    assert moved > 1e-7                                 # the ball falls and is hit within 0.1 ms


def test_series_csv_has_named_columns_with_units(drill):
    """output.series_csv: transient.csv holds the rows of transient.h5 with a header of names and units."""
    out, summary = drill
    assert "transient.csv" in summary["outputs"]
    with open(out / "transient.csv") as f:
        rows = list(csv.reader(f))
    header, values = rows[0], np.array(rows[1:], dtype=float)
    assert header[:2] == ["time_s [s]", "dt_s [s]"]
    assert "ball_position_m[1] [m]" in header and "tip_ball_closed [1]" in header
    with h5py.File(out / "transient.h5", "r") as f:
        assert values.shape[0] == f["time_s"].shape[0]
        np.testing.assert_array_equal(values[:, 0], f["time_s"][:])           # 17 digits: exact
        np.testing.assert_array_equal(values[:, header.index("ball_position_m[1] [m]")],
                                      f["ball_position_m"][:, 1])
        assert f["ball_position_m"].attrs["units"] == "m"


def test_mode_files_read_in_meshio_with_one_numbering(tmp_path):
    """The transducer's mode files: meshio reads them (time = frequency); modes are numbered from 1 in the
    XDMF grid names, the HDF5 groups, modes.csv and the summary; each shape's largest displacement is the
    stated amplitude, and the scale back to the mass-normalised shape is in the file."""
    summary = run_case_quiet("usdc-transducer.toml", tmp_path, *TRANSDUCER_MODAL, "output.mode_shape_amplitude_m=2e-3")
    modal = summary["results"]["modal"]
    frequencies = [m["resonance_Hz"] for m in modal["modes"]]
    assert [m["mode"] for m in modal["modes"]] == list(range(1, len(frequencies) + 1))
    with open(tmp_path / "modes.csv") as f:
        table = list(csv.DictReader(f))
    assert [int(r["mode"]) for r in table] == [m["mode"] for m in modal["modes"]]
    for state in ("short", "open"):
        path = tmp_path / f"modes_{state}.xdmf"
        points, cells, frames = read_series(path)
        for _, point_data, cell_data in frames:
            assert set(point_data) == {"displacement", "potential", *DEFAULT_DERIVED_NAMES}
            check_region_names(cell_data, summary["regions"])
            assert np.linalg.norm(point_data["displacement"], axis=1).max() == pytest.approx(2e-3, rel=1e-12)
        grids = [g for g in ET.parse(path).iter("Grid") if g.get("GridType") == "Uniform"]
        assert [g.get("Name").split(":")[0] for g in grids] == [f"mode {k}" for k in range(1, len(frames) + 1)]
        if state == "short":
            assert [t for t, _, _ in frames] == pytest.approx(frequencies, rel=1e-12)
    with h5py.File(tmp_path / "modes_short.h5", "r") as f:
        k = modal["working_mode"]
        attrs = f[f"mode_{k}/displacement"].attrs
        assert attrs["units"] == "m" and attrs["amplitude_m"] == 2e-3
        scale = attrs["shape_scale_m_sqrt_kg"]
        # dividing by the scale gives the mass-normalised shape back: its axial value at the tip vertex (0, 0) is
        # psi_P of the summary's modal mass 1/psi_P^2 (same shape, P1 = P2 at a vertex; 1e-9: the file's doubles)
        geometry = f["mesh/geometry"][:]
        tip_vertex = int(np.argmin(np.linalg.norm(geometry[:, :2], axis=1)))
        assert np.linalg.norm(geometry[tip_vertex]) < 1e-12
        psi_tip = f[f"mode_{k}/displacement"][tip_vertex, 1] / scale
    assert 1 / psi_tip**2 == pytest.approx(modal["modes"][k - 1]["modal_mass_at_tip_kg"], rel=1e-9)
    info = {i.get("Name"): float(i.get("Value")) for i in
            [g for g in ET.parse(tmp_path / "modes_short.xdmf").iter("Grid")
             if g.get("GridType") == "Uniform"][k - 1].iter("Information")}
    assert info["frequency_Hz"] == pytest.approx(modal["working_resonance_Hz"], rel=1e-15)
    assert info["shape_scale_m_sqrt_kg"] == pytest.approx(scale, rel=1e-15)


def test_lumped_bodies_move_as_their_series_says(tmp_path):
    """The lumped drill's bodies file (``lumped.output.bodies_interval_s``, app/lumped/bodies.py): meshio reads the
    triangles of the transducer's tip, ball, stem and rock, a frame at t = 0 and at every 0.1 ms, and each body's
    vertices are displaced, straight up, by its coordinate in the series file at the frame's time (reference:
    transient.h5's tip_displacement_m, ball_position_m, stem_position_m, rock_surface_displacement_m, zero where the
    parts rest on each other unloaded; 1e-15 m: the drawing's coordinates, 0.28 m, in doubles)."""
    summary = run_case_quiet("usdc-lumped.toml", tmp_path, "lumped.duration_s=0.002",
                             "lumped.output.bodies_interval_s=1e-4", "lumped.output.plots=false")
    assert {"transient_bodies.xdmf", "transient_bodies/bodies.h5"} <= set(summary["outputs"])
    points, (triangles,), frames = read_series(tmp_path / "transient_bodies.xdmf")
    assert triangles.type == "triangle" and len(frames) == 21
    assert [t for t, _, _ in frames] == pytest.approx([k * 1e-4 for k in range(21)], rel=1e-12, abs=0)
    with h5py.File(tmp_path / "transient_bodies" / "bodies.h5", "r") as f:
        names = [str(n) for n in f["body"].attrs["names"]]
    assert names == ["transducer", "ball", "stem", "rock"]
    columns = {"transducer": "tip_displacement_m", "ball": "ball_position_m", "stem": "stem_position_m",
               "rock": "rock_surface_displacement_m"}
    with h5py.File(tmp_path / "transient.h5", "r") as f:
        time = f["time_s"][:]
        series = {name: f[column][:].reshape(len(time), -1)[:, 0] for name, column in columns.items()}
    moved = {name: 0.0 for name in names}
    for t, point_data, cell_data in frames:
        assert set(point_data) == {"displacement"} and set(cell_data) == {"body", "sector"}
        row = int(np.argmin(np.abs(time - t)))
        assert time[row] == pytest.approx(t, rel=1e-12)
        u = point_data["displacement"]
        body = cell_data["body"][0]
        for index, name in enumerate(names):
            vertices = np.unique(triangles.data[body == index])
            expected = np.zeros((len(vertices), 3))
            expected[:, 2] = series[name][row]
            np.testing.assert_allclose(u[vertices], expected, rtol=0, atol=1e-15, err_msg=f"{name} at {t}")
            moved[name] = max(moved[name], abs(series[name][row]))
    # the initial gaps (150, 100, 50 um) and the hammering: every body but the rock moves by tens of um
    assert min(moved[name] for name in ("transducer", "ball", "stem")) > 1e-5
