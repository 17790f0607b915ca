"""Multi-phase transient drive (app/transient/driver.py VoltageDrive): each driven electrode has its
own amplitude and phase. Without contact the model is linear, so a run with two electrodes 90
degrees apart equals the sum of the runs with each electrode alone (the other at 0 V), from rest
and from the harmonic steady state (superposed per-electrode harmonic solves); and a target tip
amplitude scales all phases by one factor."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from app.case.schema import load_case
from app.errors import CaseError
from app.runner import run_transient_analysis

CASE = """
title = "two-phase PZT-4 strip"
tier = "fe"
analyses = ["transient"]

[geometry]
model = "plane_strain"
builder = "bar"
parameters = {{ length_m = 0.02, width_m = 0.002, axial_divisions = 10, lateral_divisions = 2 }}

[materials.pzt4]
library = "PZT-4"

[[regions]]
cells = "piezo"
material = "pzt4"
poling = "+z"

[[supports]]
facets = ["bottom"]
components = ["z"]

[electrodes.a]
facets = ["top"]
kind = "voltage"
amplitude_V = {a}
phase_deg = 0.0

[electrodes.b]
facets = ["bottom"]
kind = "voltage"
amplitude_V = {b}
phase_deg = 90.0

[points.end]
coordinates_m = [0.0, 0.02]
component = "z"

[output]
fields = false
plots = false

[transient]
end_time_s = 4e-6
output_interval_s = 4e-6
initial_state = "{start}"

[transient.steps]
open_s = 2e-7
closed_s = 2e-7
change_s = 2e-7

[transient.drive]
frequency_Hz = 50000.0
"""


def _run(tmp_path, name, a, b, start, overrides=()):
    comm = MPI.COMM_WORLD
    folder = tmp_path / name if comm.rank == 0 else None
    folder = comm.bcast(folder, root=0)
    if comm.rank == 0:
        folder.mkdir()
        (folder / "case.toml").write_text(CASE.format(a=a, b=b, start=start))
    comm.barrier()
    case = load_case(folder / "case.toml", list(overrides))
    results = run(case, folder / "out", comm, lambda *args: None)
    with h5py.File(folder / "out" / "transient.h5", "r") as f:
        series = {k: f[k][()] for k in ("time_s", "end_displacement_m", "a_voltage_V", "b_voltage_V")}
    return series, results


@pytest.mark.mpi
@pytest.mark.parametrize("start", ["rest", "harmonic"])
def test_two_phases_superpose(tmp_path, start):
    both, _ = _run(tmp_path, "both", 10.0, 5.0, start)
    only_a, _ = _run(tmp_path, "a", 10.0, 0.0, start)
    only_b, _ = _run(tmp_path, "b", 0.0, 5.0, start)
    np.testing.assert_array_equal(both["time_s"], only_a["time_s"])
    omega_t = 2 * np.pi * 50000.0 * both["time_s"]
    shift = np.pi / 2 if start == "harmonic" else 0.0
    np.testing.assert_allclose(both["a_voltage_V"], 10.0 * np.sin(omega_t + shift), atol=1e-12)
    np.testing.assert_allclose(both["b_voltage_V"], 5.0 * np.sin(omega_t + np.pi / 2 + shift), atol=1e-12)
    total = only_a["end_displacement_m"] + only_b["end_displacement_m"]
    scale = np.abs(both["end_displacement_m"]).max()
    assert scale > 0 and np.abs(only_b["end_displacement_m"]).max() > 1e-3 * scale
    assert np.abs(both["end_displacement_m"] - total).max() < 1e-9 * scale


@pytest.mark.mpi
def test_target_amplitude_scales_all_phases_together(tmp_path):
    nominal, _ = _run(tmp_path, "nominal", 10.0, 5.0, "harmonic")
    target, results = _run(tmp_path, "target", 10.0, 5.0, "harmonic",
                           ["transient.drive.tip_amplitude_m=1e-9", "transient.drive.point=\"end\""])
    factor = results["drive_voltage_V"] / 10.0
    np.testing.assert_allclose(target["a_voltage_V"], factor * nominal["a_voltage_V"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(target["b_voltage_V"], factor * nominal["b_voltage_V"], rtol=1e-12, atol=1e-15)
    scale = np.abs(target["end_displacement_m"]).max()
    assert np.abs(target["end_displacement_m"] - factor * nominal["end_displacement_m"]).max() < 1e-9 * scale


BELT_CASE = CASE.replace('''[electrodes.a]
facets = ["top"]
kind = "voltage"
amplitude_V = {a}
phase_deg = 0.0

[electrodes.b]
facets = ["bottom"]
kind = "voltage"
amplitude_V = {b}
phase_deg = 90.0
''', '''[electrodes.ground]
facets = ["bottom"]
kind = "ground"
''').replace('''[[supports]]
facets = ["bottom"]
components = ["z"]
''', "") + '''
[transient.loads]
fe_force_N = [0.0, -1000.0]

[[transient.bodies]]
name = "belt"                 # a rigid plane under the strip, running along x
position_m = [0.0, 0.0]
mass_kg = 1.0
free_axes = [false, false]
velocity_m_per_s = [1.0, 0.0]

[[transient.contacts]]
name = "strip_belt"
kind = "surface"
facets = "bottom"
body = "belt"
shape = "plane"
normal = [0.0, 1.0]
stiffness = 1e13
damping = 1e6

[transient.contacts.friction]
mu_dynamic = 0.25
static_ratio = 1.5
decay_s_per_m = 100.0
'''


@pytest.mark.mpi
def test_surface_friction_from_the_case_file(tmp_path):
    """The strip pressed on a belt running at 1 m/s: every contact point slips at ~1 m/s, so the
    friction force is mu(1 m/s) = mu_d (FACT, DC: mu_s at rest, 1e-43 above mu_d at 1 m/s) times
    the normal force, along the belt's motion, at every step with contact."""
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / "belt" if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        folder.mkdir()
        (folder / "case.toml").write_text(BELT_CASE.format(a=0, b=0, start="rest"))
    comm.barrier()
    case = load_case(folder / "case.toml", ["transient.end_time_s=2e-5", "transient.output_interval_s=2e-5"])
    run(case, folder / "out", comm, lambda *args: None)
    with h5py.File(folder / "out" / "transient.h5", "r") as f:
        force = f["strip_belt_force_N"][()]
        closed = f["strip_belt_closed"][()] > 0
    assert closed.sum() > 50
    normal = -force[closed, 1]                  # force on the belt: pressed down (-y), dragged back (-x)
    assert normal.min() > 0
    np.testing.assert_allclose(-force[closed, 0] / normal, 0.25, rtol=1e-6)


def test_harmonic_start_needs_a_driven_electrode(tmp_path):
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / "undriven" if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        folder.mkdir()
        (folder / "case.toml").write_text(BELT_CASE.format(a=0, b=0, start="harmonic"))
    comm.barrier()
    with pytest.raises(CaseError) as err:
        run(load_case(folder / "case.toml"), folder / "out", comm, lambda *args: None)
    assert err.value.key == "transient.initial_state"


@pytest.mark.mpi
def test_harmonic_start_is_the_harmonic_solution_at_the_electrode_amplitudes_and_phases(shared_tmp):
    """u(0) = Re X, v(0) = -omega Im X with X the harmonic response to the case's phasors (10 V at 0 deg,
    5 V at 90 deg): each electrode's amplitude and phase counted once."""
    from app.fe.operators import Operators
    from app.harmonic import HarmonicSolver
    from app.transient.driver import PointSampler, build

    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        (shared_tmp / "case.toml").write_text(CASE.format(a=10.0, b=5.0, start="harmonic"))
    comm.barrier()
    tm = build(load_case(shared_tmp / "case.toml"), comm, lambda *args: None)
    state, voltage = tm.initial_state()
    solver = HarmonicSolver(tm.model, Operators(tm.fe.K, tm.fe.M, tm.fe.C), voltage)   # the case's phasors
    expected = solver.solve(50000.0).displacement_m["end"]
    solver.destroy()
    sampler = PointSampler(tm.model)
    omega = 2 * np.pi * 50000.0
    assert sampler.values(state.u)["end"] == pytest.approx(expected.real, rel=1e-9, abs=1e-12 * abs(expected))
    assert sampler.values(state.v)["end"] == pytest.approx(-omega * expected.imag, rel=1e-9,
                                                         abs=1e-12 * omega * abs(expected))


def run(case, out_dir, comm, log, resume=False):
    """The case's transient analysis through the one run loop (the FE tier's engine), as ``piezodyn run`` does."""
    out_dir = Path(out_dir)
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    return run_transient_analysis(case, out_dir, comm, log, resume)
