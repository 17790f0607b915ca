"""The contact pressure in the modal tier (``output.contact_pressure``, docs/fields.md): the motor on the tests'
coarse stator (tests/test_cases.py's reduced model: 4 mm / 2 mm, 16 interface nodes, 64 ring sites) for 0.1 ms,
field bursts of 20 frames (every other step) over a period every 2.95 periods: from 0 and from 82 us, where the
rotor bounces on the wave's crests.

The modal tier evaluates the contact law at its sites and writes their pressure, under the FE tier's name
``contact_pressure_Pa`` [Pa], as the point cloud ``transient_contact_sites.xdmf`` (the sites moving with the
stator, each with its area ``site_area_m2``), and each step's peak as ``<contact>_peak_pressure_Pa`` like the FE
tier. ParaView's readers open the cloud in tests/test_paraview.py, where the FE tier's field of the same name is
read too.
"""

from __future__ import annotations

import re

import h5py
import meshio
import numpy as np
import pytest
from conftest import run_case_quiet
from test_transient_checkpoint import frame_group

MOTOR_COARSE = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.tip_mesh_size_m=0.002",
                "reduction.interface_nodes=16", "transient.contacts[0].sample_points=64", "output.plots=false"]
BURST = ["transient.end_time_s=1e-4", "output.contact_pressure=true", "output.field_interval_periods=2.95",
         "output.field_phases=20"]


@pytest.fixture(scope="module")
def motor(tmp_path_factory):
    out = tmp_path_factory.mktemp("motor_pressure")
    summary = run_case_quiet("wwusm-motor.toml", out, *MOTOR_COARSE, *BURST)
    return out, summary


def frames(out) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(time [s], site displacement, site pressure) of every frame of the cloud, from its frames' groups."""
    times = [float(v) for v in re.findall(r'<Time Value="([^"]+)"', (out / "transient_contact_sites.xdmf").read_text())]
    out_frames = []
    for k, t in enumerate(times):
        with frame_group(out, k, "transient_contact_sites.xdmf") as f:
            pressure = f["contact_sites/contact_pressure_Pa"]
            assert f.units("contact_sites/contact_pressure_Pa") == "Pa"
            out_frames.append((t, f["contact_sites/displacement"][:], pressure[:]))
    return out_frames


def test_site_pressures_integrate_to_the_reported_normal_force(motor):
    """Reference: the run's own normal-force column (transient.h5 ``stator_rotor_normal_force_N``), the sum of the
    site forces that the compiled step's contact law gave (app/reduced/kernel.py ``_record``), taken at the same
    step. The file's pressure is evaluated afterwards, outside the loop, from the coordinates q, q' and the rotor's
    state (engine ``_site_pressures``); sum(pressure x area) over the sites is the normal force it stands for. With
    the motor's Newmark scheme (alpha_f = 0) the step's law is evaluated at the end-of-step state the file shows,
    so the two agree to round-off: 1e-9 relative (a pressure not divided by the area, taken at the start of the
    step, or of other sites is off by orders more). The step's peak pressure column is the largest site pressure
    of the frame the same way, and the run's max_pressure_Pa the column's largest."""
    out, summary = motor
    with h5py.File(out / "transient_fields" / "contact_sites.h5", "r") as f:
        area = f["site_area_m2"][:]
        assert [str(n) for n in f["contact"].attrs["names"]] == ["stator_rotor"]
        assert f["site_area_m2"].attrs["units"] == "m^2"
    with h5py.File(out / "transient.h5", "r") as f:
        time = f["time_s"][:]
        normal = f["stator_rotor_normal_force_N"][:]
        peak = f["stator_rotor_peak_pressure_Pa"][:]
        assert f["stator_rotor_peak_pressure_Pa"].attrs["units"] == "Pa"
    assert area.size == 64 and area.min() > 0
    series = frames(out)
    assert len(series) == summary["results"]["transient"]["field_outputs"] >= 30       # 20 + the second burst
    closed = 0
    for t, displacement, pressure in series[1:]:       # the frame at t = 0 has no row: rows start after a step
        row = int(np.argmin(np.abs(time - t)))
        assert time[row] == pytest.approx(t, rel=1e-12)
        assert pressure.min() >= 0.0
        assert np.sum(pressure * area) == pytest.approx(normal[row], rel=1e-9, abs=1e-9 * normal.max())
        assert pressure.max() == pytest.approx(peak[row], rel=1e-9, abs=0)
        assert np.linalg.norm(displacement, axis=1).min() > 1e-7          # the sites ride the stator's wave (um)
        closed += normal[row] > 0.1
    assert closed >= 3                                  # measured: 4 of the 33 frames carry more than 0.1 N
    assert summary["results"]["transient"]["contacts"]["stator_rotor"]["max_pressure_Pa"] == peak.max() > 1e5


def test_site_cloud_reads_in_meshio_moving_with_the_stator(motor):
    """meshio reads the cloud (one vertex cell per site) with the documented point data (docs/fields.md): the
    pressure under the FE tier's name and unit, the displacement that moves the sites with the stator, their area
    and contact; its times are the field series'."""
    out, _ = motor
    with meshio.xdmf.TimeSeriesReader(out / "transient_contact_sites.xdmf") as reader:
        points, cells = reader.read_points_cells()
        data = [reader.read_data(k) for k in range(reader.num_steps)]
    with meshio.xdmf.TimeSeriesReader(out / "transient_fields.xdmf") as reader:
        reader.read_points_cells()
        field_times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
    (vertices,) = cells
    assert vertices.type == "vertex" and len(vertices.data) == len(points) == 64
    assert [t for t, _, _ in data] == field_times
    # the sites on the stator's contact circle (the rotor's contact radius, the tooth tops)
    radius = np.linalg.norm(points[:, :2], axis=1)
    assert np.ptp(radius) < 1e-9 * radius.max() and np.ptp(points[:, 2]) < 1e-9
    series = frames(out)
    for (t, point_data, _), (t_file, displacement, pressure) in zip(data, series):
        assert set(point_data) == {"displacement", "contact_pressure_Pa", "site_area_m2", "contact"}
        assert t == t_file
        np.testing.assert_array_equal(point_data["contact_pressure_Pa"], pressure)
        np.testing.assert_array_equal(point_data["displacement"], displacement)
