"""Checkpoints, ``--resume`` and field output of the modal tier (``tier = "modal"``), with the FE
tier's guarantees and its kill machinery (app/killpoint.py, tests/test_transient_checkpoint.py): a
run split in two, or killed with SIGKILL at any moment and resumed, gives the series of the run in
one go, and the XDMF fields (x = T q at the output interval) are those of the reduced solution.

Bit-identity: a resumed run loads the reduced model and the kernel's complete state from the
checkpoint, so it repeats the interrupted run's steps exactly, on any number of ranks
(app/loop/checkpoint.py, app/reduced/engine.py). The reference run reduced its model in another process; where that
reduction came out bit-identical too (always, serially, in our runs: same files compared), the
series must be identical (rtol 0); where it did not (the 2-rank kill tests reduce on a different
partition than the serial reference), to the FE tier's solver tolerance."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES, run_case_quiet, run_cli
from mpi4py import MPI
from test_transient_checkpoint import (
    PARALLEL_RTOL,
    assert_readable_outputs,
    assert_same_series,
    frame_files,
    frame_group,
    named_frame_files,
    read_series,
    xdmf_times,
)

CASE = "usdc-fe.toml"
TINY = ['tier="modal"', "geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "output.plots=false"]
END_S = 2e-4
# ~820 steps to 0.2 ms; field outputs at t = 0 and 7 more over the first drive period (~50 us);
# checkpoints after steps 100, 200, ..., 800 and at the end (9 in all)
KILL_SETS = [*TINY, f"transient.end_time_s={END_S!r}", "transient.checkpoint_interval_steps=100"]
MODEL = Path("checkpoint") / "reduced-model.npz"


def _sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def same_reduced_model(a: Path, b: Path) -> bool:
    """Whether two runs reduced to bit-identical models (then their series must be identical)."""
    with np.load(a / MODEL) as x, np.load(b / MODEL) as y:
        return sorted(x.files) == sorted(y.files) and all(np.array_equal(x[k], y[k]) for k in x.files)


def assert_resumed_equals(reference: Path, out: Path, other_partition: bool = False) -> None:
    """The resumed run in ``out`` against the one-go run in ``reference``: the time series bit for
    bit if both reduced to the same model; the fields bit for bit if they were also expanded on the
    same partition (T q and its vertex sampling sum in the partition's order), else to round-off."""
    exact = same_reduced_model(reference, out)
    assert exact or other_partition, "serial runs reduced to different models"
    assert_same_series(read_series(reference / "transient.h5"), read_series(out / "transient.h5"),
                       rtol=0.0 if exact else PARALLEL_RTOL)
    np.testing.assert_allclose(xdmf_times(out), xdmf_times(reference), rtol=0.0 if exact else 1e-12)
    for k in range(len(xdmf_times(reference))):
        name = f"frame {k}"
        with frame_group(reference, k) as f, frame_group(out, k) as g:
            for field in ("displacement", "potential"):
                a, b = f[field][:], g[field][:]
                if exact and not other_partition:
                    np.testing.assert_array_equal(a, b)
                else:
                    rtol = 1e-12 if exact else PARALLEL_RTOL
                    assert np.abs(a - b).max() <= rtol * np.abs(a).max(), (name, field)


@pytest.fixture(scope="module")
def one_go_cli(tmp_path_factory):
    """The reference: the tiny drill scene in the modal tier to END_S in one go, in a fresh process."""
    out = tmp_path_factory.mktemp("modal_one_go")
    if MPI.COMM_WORLD.size == 1:
        result = run_cli("run", CASES / CASE, "--out", out, "--quiet", *_sets(KILL_SETS))
        assert result.returncode == 0, result.stderr[-2000:]
    return out


@pytest.mark.mpi
def test_modal_resume_from_half_time_equals_one_run(shared_tmp):
    """In process, on 1 or 2 ranks: to a time on the reference's step grid, then --resume to END_S."""
    comm = MPI.COMM_WORLD
    reference_dir = shared_tmp / "one_go"
    summary_ref = run_case_quiet(CASE, reference_dir, *KILL_SETS)
    reference = comm.bcast(read_series(reference_dir / "transient.h5") if comm.rank == 0 else None)
    t_half = float(reference["time_s"][reference["time_s"].size // 2])
    split = shared_tmp / "split"
    first = run_case_quiet(CASE, split, *KILL_SETS[:-2], f"transient.end_time_s={t_half!r}",
                           "transient.checkpoint_interval_steps=100")
    assert first["results"]["transient"]["checkpoints_written"] >= 4
    from app.runner import run_case

    second = run_case(CASES / CASE, KILL_SETS, split, quiet=True, resume=True)
    comm.barrier()
    res_ref, res = summary_ref["results"]["transient"], second["results"]["transient"]
    assert res["resumed_from_s"] == pytest.approx(t_half, rel=1e-15)
    assert res["reduction"]["from_checkpoint"] and not res_ref["reduction"]["from_checkpoint"]
    for key in ("steps", "attempts", "cutbacks", "event_refinements", "newton_iterations", "field_outputs"):
        assert res[key] == res_ref[key], key
    assert sorted(res["contacts"]) == sorted(res_ref["contacts"])
    if comm.rank == 0:
        # one process: the reduction repeats bit for bit, so the series does too
        assert_resumed_equals(reference_dir, split, other_partition=comm.size > 1)
        assert sorted(second["outputs"]) == sorted(
            str(p.relative_to(split)) for p in split.rglob("*") if p.is_file())


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial and 2-rank subprocesses")
def test_serial_modal_checkpoint_resumes_on_two_ranks(one_go_cli, tmp_path):
    """The reduced model and T are stored per input cell: a serial checkpoint continues on 2 ranks
    with the very same reduced model, so the series is the one-go series bit for bit."""
    reference = read_series(one_go_cli / "transient.h5")
    t_half = float(reference["time_s"][reference["time_s"].size // 2])
    first = run_cli("run", CASES / CASE, "--out", tmp_path, "--quiet", *_sets(KILL_SETS),
                    "--set", f"transient.end_time_s={t_half!r}")
    assert first.returncode == 0, first.stderr[-2000:]
    second = run_cli("run", CASES / CASE, "--resume", tmp_path, "--quiet", *_sets(KILL_SETS), mpi=2)
    assert second.returncode == 0, second.stderr[-2000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["mpi_size"] == 2
    assert summary["results"]["transient"]["resumed_from_s"] == pytest.approx(t_half, rel=1e-15)
    assert_resumed_equals(one_go_cli, tmp_path, other_partition=True)


# ------------------------------------------------------------------ kill anywhere, resume to the same series
KILL_POINTS = [
    "harmonic_start:1",        # after the reduced harmonic start: no checkpoint yet, --resume starts again
    "fields_written:1",        # right after the t = 0 field output, before any checkpoint
    "series_block:1",          # the first 100 rows written, their checkpoint not yet
    "checkpoint_state:1",      # the first checkpoint's state file written, its JSON not
    "checkpoint_tmp:1",        # half the first checkpoint JSON in its temporary file
    "series_block:5",          # rows of a later block written, 5 steps after a checkpoint
    "fields_data:1",           # the one batch's HDF5 (frames 0-7, carried in checkpoints 1-8's records) written
                               # at the end, the XDMF not yet naming it: resumed from checkpoint 8's buffer
    "fields_written:7",        # right after a field output, frames buffered (the batch) across checkpoint 1
    "checkpoint_tmp:5",        # a later checkpoint half written
    "checkpoint_state:8",      # the last interval checkpoint
    "fields_written:8",        # right after the last output (the end of the first period's burst)
    "checkpoint_tmp:9",        # during the final checkpoint at the end time
]
KILL_POINTS_FAST = ["harmonic_start:1", "checkpoint_tmp:1", "series_block:5", "fields_written:2",
                    "checkpoint_state:8"]


def kill_and_resume(point: str, out: Path, reference: Path, mpi: int = 0) -> None:
    killed = run_cli("run", CASES / CASE, "--out", out, "--quiet", *_sets(KILL_SETS), mpi=mpi, kill_at=point)
    assert killed.returncode != 0, f"{point}: the run was not killed"
    assert not (out / "summary.json").exists()
    assert_readable_outputs(out)
    resumed = run_cli("run", CASES / CASE, "--resume", out, "--quiet", *_sets(KILL_SETS), mpi=mpi)
    assert resumed.returncode == 0, f"{point}: " + resumed.stderr[-3000:]
    assert_resumed_equals(reference, out, other_partition=bool(mpi))
    assert_readable_outputs(out)
    summary = json.loads((out / "summary.json").read_text())
    for name in summary["outputs"]:
        assert (out / name).is_file(), f"{point}: {name}"
    assert frame_files(out) == named_frame_files(out)          # no frame file of the killed run left over
    assert not list((out / "checkpoint").glob("*.tmp"))


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial subprocesses")
@pytest.mark.parametrize("point", KILL_POINTS_FAST)
def test_modal_run_killed_anywhere_resumes_to_the_one_go_series(one_go_cli, tmp_path, point):
    kill_and_resume(point, tmp_path, one_go_cli)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives 2-rank subprocesses")
@pytest.mark.parametrize("point", ["checkpoint_tmp:1", "fields_written:2"])
def test_modal_run_killed_on_two_ranks_resumes_to_the_one_go_series(one_go_cli, tmp_path, point):
    kill_and_resume(point, tmp_path, one_go_cli, mpi=2)


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial and 2-rank subprocesses")
@pytest.mark.parametrize("mpi", [0, 2])
@pytest.mark.parametrize("point", KILL_POINTS)
def test_modal_run_killed_at_every_point_resumes_to_the_one_go_series(one_go_cli, tmp_path, point, mpi):
    kill_and_resume(point, tmp_path, one_go_cli, mpi=mpi)


# ------------------------------------------------------------------ field output
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="reads the serial reference run")
def test_expanded_fields_equal_the_reduced_solution_at_the_output_times(one_go_cli):
    """x = T q written at the FE tier's frame times (phase-locked by default: t = 0 and the first step at or
    after each j / 8 of the first drive period), P1 displacement and potential on the FE grid plus the rigid
    bodies; at the tip node (the interface DOF of the ball contact, also the drive point) the
    written field equals the time series' tip displacement (sample row @ q) at that step."""
    import h5py

    out = one_go_cli
    summary = json.loads((out / "summary.json").read_text())
    res = summary["results"]["transient"]
    times = xdmf_times(out)
    assert res["field_outputs"] == 8 == len(times) and res["fields"] == "transient_fields.xdmf"
    series = read_series(out / "transient.h5")
    with h5py.File(out / "transient_fields" / "mesh.h5", "r") as f:
        geometry = f["mesh/geometry"][:]
        assert len(np.unique(f["mesh/region"][:])) >= 3
    tip = int(np.argmin(np.linalg.norm(geometry[:, :2], axis=1)))      # the vertex at (r, z) = (0, 0)
    assert np.linalg.norm(geometry[tip]) < 1e-12
    for k, t in enumerate(times):
        assert k / 20100.0 / 8 <= t < k / 20100.0 / 8 + 1e-6 + 1e-12
        with frame_group(out, k) as f:
            u, phi = f["displacement"][:], f["potential"][:]
            assert u.shape == (geometry.shape[0], 3) and phi.shape == (geometry.shape[0],)
            assert f.time_s == t and f.units("displacement") == "m" and f.units("potential") == "V"
        assert 1e-6 < np.abs(u[:, 1]).max() < 30e-6                  # the tip vibrates at ~15 um
        assert np.ptp(phi) > 1.0                                       # volts across the ceramic
        if k == 0:
            continue                                                   # t = 0 has no series row
        (row,) = np.flatnonzero(series["time_s"] == t)
        expected = series["tip_displacement_m"][row]
        assert abs(expected) > 1e-7
        assert u[tip, 1] == pytest.approx(expected, rel=1e-12)
    # the bodies with their shapes: the companion file, one grid of all bodies per output time
    text = (out / "transient_bodies.xdmf").read_text()
    assert text.count('<Grid Name="rigid_bodies"') == len(times)
    with h5py.File(out / "transient_fields" / "bodies.h5", "r") as f:
        assert [str(n) for n in f["body"].attrs["names"]] == ["ball", "stem", "rock"]
    for name in ("transient_fields.xdmf", "transient_fields/mesh.h5", "transient_fields/frames_000000.h5",
                 "transient_bodies.xdmf", "transient_fields/bodies.h5",
                 "checkpoint/checkpoint.json", "checkpoint/reduced-model.npz", "summary.json"):
        assert name in summary["outputs"]
    assert sorted(summary["outputs"]) == sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())


@pytest.mark.mpi
def test_no_field_output_without_output_fields(shared_tmp):
    summary = run_case_quiet(CASE, shared_tmp, *TINY, "transient.end_time_s=5e-5", "transient.output_interval_s=5e-5",
                             "output.fields=false")
    res = summary["results"]["transient"]
    assert res["fields"] is None and res["field_outputs"] == 0 and res["steps"] > 100
    assert not (shared_tmp / "transient_fields.xdmf").exists() and not (shared_tmp / "transient_fields").exists()
    assert "checkpoint/reduced-model.npz" in summary["outputs"]


def test_modal_resume_errors_are_one_line(capsys, one_go_cli, tmp_path):
    """Exit 2 with one line naming the file and key: another tier, a missing or damaged reduced
    model, an end time before the checkpoint."""
    from test_bad_input_suite import assert_one_line, cli_main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")
    out = tmp_path / "copy"
    shutil.copytree(one_go_cli, out)
    sets = _sets(KILL_SETS)
    assert_one_line(*cli_main(capsys, "run", CASES / CASE, "--resume", out, *sets, "--set", 'tier="fe"'),
                    CASE, "tier")
    assert_one_line(*cli_main(capsys, "run", CASES / CASE, "--resume", out, *sets,
                              "--set", "transient.end_time_s=1e-4"), CASE, "transient.end_time_s")
    model = out / MODEL
    model.write_bytes(model.read_bytes()[:1000])
    assert_one_line(*cli_main(capsys, "run", CASES / CASE, "--resume", out, *sets), str(model), "corrupt")
    model.unlink()
    assert_one_line(*cli_main(capsys, "run", CASES / CASE, "--resume", out, *sets), "checkpoint.json",
                    "reduced_model", "missing")


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="compares two serial in-process runs")
def test_frames_taken_inside_the_kernel_are_the_loops(tmp_path, monkeypatch):
    """The modal kernel takes the field frames at its steps (app/reduced/kernel.py Frames), with a buffer of 1
    frame and 1 frame time per call here and 32 frames per period (a frame every ~6 steps, the loop's progress
    stops every 8), so a call returns for more times after each frame and the next frame is often due before the
    loop's next stop, against
    the loop stopping the kernel at every frame time (FieldSeriesExport.engine_can_take false: the path of a
    series with a contact site cloud): the same frames (times, coordinates, fields) and series, bit for bit (the
    rule and the float comparisons are the loop's, and a call boundary does not change a step)."""
    from app.reduced import engine as modal
    from app.transient import fields as series_module

    taken = []
    original = modal.ModalEngine.taken_frames
    monkeypatch.setattr(modal.ModalEngine, "taken_frames", lambda self: _record(taken, original(self)))
    monkeypatch.setattr(modal, "FRAMES_PER_CALL", 1)
    monkeypatch.setattr(modal, "FRAME_TIMES_PER_CALL", 1)
    sets = [*TINY, "transient.end_time_s=1e-4", "output.field_interval_periods=1", "output.field_phases=32"]
    run_case_quiet(CASE, tmp_path / "kernel", *sets)
    assert len(taken) == 64        # 32 frames in each of two drive periods and the first of the third at 99.5 us;
    #                                t = 0 is the loop's
    monkeypatch.setattr(series_module.FieldSeriesExport, "engine_can_take", property(lambda self: False))
    taken.clear()
    run_case_quiet(CASE, tmp_path / "loop", *sets)
    assert not taken
    a, b = tmp_path / "kernel", tmp_path / "loop"
    assert_same_series(read_series(a / "transient.h5"), read_series(b / "transient.h5"), rtol=0.0)
    assert list(xdmf_times(a)) == list(xdmf_times(b)) and len(xdmf_times(a)) == 65
    for name in ("transient_fields.xdmf", "transient_bodies.xdmf"):
        assert (a / name).read_text() == (b / name).read_text()
    for k in range(65):
        with frame_group(a, k) as f, frame_group(b, k) as g:
            assert f.names() == g.names() and len(f.names()) >= 3 and f.time_s == g.time_s
            for name in f.names():
                np.testing.assert_array_equal(f[name][()], g[name][()])
                assert dict(f.f[name].attrs) == dict(g.f[name].attrs)


def _record(into: list, frames: list) -> list:
    into.extend(frames)
    return frames
