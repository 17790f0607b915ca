"""Checkpoints and ``--resume`` of the motor in the modal tier (the one run loop, app/loop/loop.py).

A resumed run continues from the checkpoint's complete state (stator coordinates, rotor, energies, counters,
the steady-state watch's cycle means, the per-site diagnostics' sums) with the checkpoint's own reduced stator,
through the same deterministic compiled loop: it repeats the interrupted run's periods, so the time series, the
summary's operating point and the ring and path CSVs equal the run in one go bit for bit (rtol 0,
not a tolerance), whether the run was split, or killed with SIGKILL (app/killpoint.py) right after a time-series
flush, with a checkpoint's state file written and its JSON not, or with half a JSON in its temporary file.

The run: the coarse test stator of tests/test_motor_modal.py (its reduced model built once into the tests'
cache, PIEZODYN_CACHE_DIR of tests/conftest.py, which the subprocesses share), at most 12 drive periods,
checkpoints every 2 periods (80 steps), a steady-state window of 4 periods and a loose tolerance (0.8) so
that the steady-state rule stops the free rotor at period 10: the stop decision then needs the cycle means of
periods before the checkpoint, and the summary's window spans it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import PINNED_MOTOR, run_case_quiet, run_cli
from mpi4py import MPI
from test_transient_checkpoint import assert_readable_outputs, read_series

CASE = PINNED_MOTOR
SETS = ["geometry.parameters.mesh_size_m=0.003", "geometry.parameters.tip_mesh_size_m=0.001",
        "reduction.interface_nodes=32", "transient.contacts[0].sample_points=128", "output.plots=false",
        "output.fields=false",
        "transient.end_time_s=3.4e-4", "transient.checkpoint_interval_steps=80",
        "transient.steady_state.window_cycles=4", "transient.steady_state.min_cycles=1",
        "transient.steady_state.relative_tolerance=0.8"]
#: checkpoints after periods 2, 4, 6, 8 and at the steady stop (period 10, the 5th)
HALF_S = 6 / 36065.0             # 6 periods (240 steps of the case's dt = 1 / (40 f): the split on a step)
#: wall-clock entries and the ones that say how the run went, not what it computed
RUN_KEYS = {"wall_time_s", "setup_wall_s", "wall_s_per_simulated_ms", "resumed_from_s", "checkpoints_written",
            "checkpoint_wall_s", "stepping_wall_time_s", "field_output_wall_s"}
REDUCTION_RUN_KEYS = {"from_checkpoint", "from_cache", "setup_wall_s", "kernel_load_wall_s", "build_wall_s"}


def _cli_sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def _computed(transient: dict) -> dict:
    out = {k: v for k, v in transient.items() if k not in RUN_KEYS and k != "outputs"}
    out["reduction"] = {k: v for k, v in transient["reduction"].items() if k not in REDUCTION_RUN_KEYS}
    return out


def assert_same_run(reference: Path, out: Path) -> None:
    """The run in ``out`` is the one in ``reference`` bit for bit: series, summary results, CSVs, end state."""
    a, b = read_series(reference / "transient.h5"), read_series(out / "transient.h5")
    assert sorted(a) == sorted(b)
    for name in a:
        np.testing.assert_array_equal(b[name], a[name], err_msg=name)
    ref = json.loads((reference / "summary.json").read_text())["results"]["transient"]
    res = json.loads((out / "summary.json").read_text())["results"]["transient"]
    assert _computed(res) == _computed(ref)
    for name in ("motor_ring.csv", "motor_contact_path.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name


@pytest.fixture(scope="module")
def one_go(tmp_path_factory):
    """The reference: the run in one go, in this process (the reduced model from the tests' cache)."""
    out = Path(MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp("motor_one_go")), root=0))
    summary = run_case_quiet(CASE, out, *SETS)
    res = summary["results"]["transient"]
    # the set-up the kill points below rely on: stopped by the steady-state rule, after 5 checkpoints
    steady = res["steady_state"]
    # the watch leaves out the period the run starts in (entered at its first step), so period 10 closes 9 means
    assert steady["steady"] and steady["cycles"] == 9 and res["checkpoints_written"] == 5, steady["cycles"]
    return out


@pytest.mark.mpi
def test_motor_resume_from_half_time_equals_one_run(one_go, shared_tmp):
    """In process, on 1 or 2 ranks: to 6 periods, then --resume to the end: the one-go run bit for bit (on 2 ranks
    every rank runs the loop on the same reduced model, from the cache or the checkpoint; rank 0 writes)."""
    from app.runner import run_case

    comm = MPI.COMM_WORLD
    first = run_case_quiet(CASE, shared_tmp, *SETS, f"transient.end_time_s={HALF_S!r}")
    assert first["results"]["transient"]["steady_state"]["cycles"] == 5
    assert not first["results"]["transient"]["steady_state"]["steady"]
    second = run_case(CASE, SETS, shared_tmp, quiet=True, resume=True)
    comm.barrier()
    res = second["results"]["transient"]
    assert res["resumed_from_s"] == first["results"]["transient"]["simulated_time_s"]
    assert res["reduction"]["from_checkpoint"]
    if comm.rank == 0:
        assert_same_run(one_go, shared_tmp)
        assert sorted(second["outputs"]) == sorted(
            str(p.relative_to(shared_tmp)) for p in shared_tmp.rglob("*") if p.is_file())
        for name in ("checkpoint/run.json", "checkpoint/checkpoint.json", "checkpoint/reduced-model.npz"):
            assert name in second["outputs"]


# ------------------------------------------------------------------ killed at the worst moments
KILL_POINTS = [
    "harmonic_start:1",        # after the harmonic start, before any output: --resume starts again
    "series_block:4",          # period 4's rows flushed, the checkpoint due at period 4 not written
    "checkpoint_state:2",      # the 2nd checkpoint's state file written, its JSON not (the 1st is the one)
    "checkpoint_tmp:3",        # half the 3rd checkpoint's JSON in its temporary file
    "series_block:9",          # period 9 flushed, 1 period after the checkpoint: the stop at 10 needs its means
    "checkpoint_tmp:5",        # the final checkpoint (the steady stop) torn: the resumed run repeats period 10
]


def kill_and_resume(point: str, out: Path, reference: Path, mpi: int = 0, resume_mpi: int | None = None) -> None:
    killed = run_cli("run", CASE, "--out", out, "--quiet", *_cli_sets(SETS), mpi=mpi, kill_at=point)
    assert killed.returncode != 0, f"{point}: the run was not killed"
    assert not (out / "summary.json").exists()
    assert_readable_outputs(out)
    resumed = run_cli("run", CASE, "--resume", out, "--quiet", *_cli_sets(SETS),
                      mpi=mpi if resume_mpi is None else resume_mpi)
    assert resumed.returncode == 0, f"{point}: " + resumed.stderr[-3000:]
    assert_same_run(reference, out)
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["outputs"]) == sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert not list((out / "checkpoint").glob("*.tmp"))
    assert len(list((out / "checkpoint").glob("state-*.npz"))) == 1


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial subprocesses")
@pytest.mark.parametrize("point", KILL_POINTS)
def test_motor_run_killed_at_the_worst_moments_resumes_to_the_one_go_run(one_go, tmp_path, point):
    kill_and_resume(point, tmp_path, one_go)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives 2-rank subprocesses")
@pytest.mark.parametrize("point, mpi", [("checkpoint_tmp:3", 0), ("series_block:9", 2)])
def test_motor_run_resumes_on_two_ranks(one_go, tmp_path, point, mpi):
    """Killed on 1 or 2 ranks, resumed on 2: every rank reads the checkpoint's reduced stator and state (rank 0's),
    so the 2-rank run repeats the serial one bit for bit."""
    kill_and_resume(point, tmp_path, one_go, mpi=mpi, resume_mpi=2)
    assert json.loads((tmp_path / "summary.json").read_text())["mpi_size"] == 2


# ------------------------------------------------------------------ bad resumes: one line, exit 2
def test_motor_resume_errors_are_one_line(capsys, one_go, tmp_path):
    """Another case (a changed preload, named by its key), no checkpoint, a damaged checkpoint record, state file,
    reduced stator or time series: exit 2, one line naming the file and the key, no traceback. A finished run
    resumed takes no step and writes the same summary. (And a run shorter than one drive period.)"""
    from test_bad_input_suite import assert_one_line, cli_main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")
    sets = _cli_sets(SETS)

    def resume(out, *more):
        return cli_main(capsys, "run", CASE, "--resume", out, "--quiet", *sets, *more)

    out = tmp_path / "copy"
    shutil.copytree(one_go, out)
    code, err = resume(out)
    assert code == 0, err
    assert_same_run(one_go, out)
    summary = json.loads((out / "summary.json").read_text())["results"]["transient"]
    assert summary["wall_s_per_simulated_ms"] is None and summary["checkpoints_written"] == 0

    assert_one_line(*resume(out, "--set", "transient.bodies[0].applied_force_N=[0.0, 0.0, -4.116]"), CASE,
                    "transient.bodies[0].applied_force_N", "differs")
    assert_one_line(*resume(out, "--set", "transient.end_time_s=1e-4"), CASE, "transient.end_time_s")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_one_line(*resume(empty), str(empty), "--resume", "no checkpoint")

    checkpoint = out / "checkpoint"
    series = out / "transient.h5"
    series.rename(tmp_path / "series.h5")
    assert_one_line(*resume(out), str(series), "missing")
    (tmp_path / "series.h5").rename(series)
    state = next(checkpoint.glob("state-*.npz"))
    good = state.read_bytes()
    state.write_bytes(good[:len(good) // 2])
    assert_one_line(*resume(out), str(state), "corrupt")
    state.write_bytes(good)
    model = checkpoint / "reduced-model.npz"
    model.write_bytes(model.read_bytes()[:1000])
    assert_one_line(*resume(out), str(model), "corrupt")
    model.unlink()
    assert_one_line(*resume(out), "checkpoint.json", "files.reduced_model", "missing")
    pointer = checkpoint / "checkpoint.json"
    pointer.write_text(pointer.read_text()[:200])
    assert_one_line(*resume(out), str(pointer), "not valid JSON")
