"""The lumped tier through the one run loop: checkpoints and ``piezodyn run --resume DIR``.

Reference: the same case run in one go. The lumped model is exact between events on an absolute integer time
lattice, its whole state is in the integrator's arrays and rank 0 alone integrates, so a run split anywhere,
or killed anywhere and resumed, must give the one-go series and event table BIT FOR BIT (tolerance 0), serially
and on 2 ranks. Damaged checkpoints and checkpoints of another tier or case are refused with one line."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES, run_case_quiet, run_cli
from mpi4py import MPI

from app.errors import CaseError
from app.series import read_time_series

CASE = "usdc-lumped.toml"
# 20 ms: 2000 rows of 10 us, ~70 events; a checkpoint every 300 rows (at 300 ... 1800) and at the end (the 7th)
SETS = ["lumped.duration_s=0.02", "lumped.output.plots=false", "lumped.output.checkpoint_interval_steps=300"]
COUNTERS = ("events", "zeno_holds", "grazing_checks_skipped_by_hermite", "bisections")


def _cli_sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def assert_identical(reference: Path, other: Path) -> None:
    """Every dataset of the two series files (time rows and the event table) equal, bit for bit."""
    a, b = read_time_series(reference / "transient.h5"), read_time_series(other / "transient.h5")
    assert sorted(a) == sorted(b)
    assert a["events"].shape[0] > 10                    # the run has impacts: the table is exercised
    for name in a:
        assert a[name].shape == b[name].shape, name
        assert np.array_equal(a[name], b[name]), f"{name}: differs"


def assert_same_results(reference: dict, other: dict) -> None:
    """The summaries' physics (statistics, per-contact sums, ledger, counters) equal: all are functions of the
    identical series, event table and integrator state."""
    ra, rb = reference["results"]["lumped"], other["results"]["lumped"]
    for key in ("statistics", "contacts", "energy_ledger", "parameters", "steps", "simulated_time_s"):
        assert ra[key] == rb[key], key
    for key in COUNTERS:
        assert ra["solver"][key] == rb["solver"][key], key


def _world_tmp(tmp_path_factory, name: str) -> Path:
    return Path(MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp(name)), root=0))


@pytest.fixture(scope="module")
def one_go(tmp_path_factory):
    """The reference, in this process (on every rank of an MPI pass)."""
    out = _world_tmp(tmp_path_factory, "lumped_one_go")
    summary = run_case_quiet(CASE, out, *SETS)
    return out, summary


@pytest.mark.mpi
def test_split_run_equals_one_go(one_go, shared_tmp):
    """End at 12.34 ms (between checkpoints, not on a progress or checkpoint boundary), resume to 20 ms."""
    from app.runner import run_case

    out_ref, summary_ref = one_go
    first = run_case_quiet(CASE, shared_tmp, "lumped.duration_s=0.01234", *SETS[1:])
    assert first["results"]["lumped"]["steps"] == 1234
    second = run_case(CASES / CASE, SETS, shared_tmp, quiet=True, resume=True)
    MPI.COMM_WORLD.barrier()
    if MPI.COMM_WORLD.rank == 0:
        assert_identical(out_ref, shared_tmp)
    assert_same_results(summary_ref, second)
    lumped = second["results"]["lumped"]
    assert lumped["resumed_from_s"] == pytest.approx(0.01234, rel=1e-15)
    assert lumped["checkpoints_written"] == 3            # at 1500, 1800 and the end (2000)
    assert lumped["statistics"]["transducer"] == summary_ref["results"]["lumped"]["statistics"]["transducer"]


def test_integrator_chunks_and_restores_bit_identically():
    """The integrator alone: random chunk sizes (1 to 700 intervals) and a restore into a new integrator from
    its state arrays give the one-call samples, events and ledger bit for bit."""
    from app.case.schema import load_case
    from app.lumped.parameters import derive_parameters
    from app.lumped.simulate import LumpedIntegrator, initial_state_from_section

    section = load_case(CASES / CASE, ["lumped.duration_s=0.03"]).lumped
    p = derive_parameters(section)

    def make():
        return LumpedIntegrator(p, section.output.output_interval_s, initial_state_from_section(p, section.initial),
                                section.solver)

    one = make()
    t, y, mode, events = one.advance(3000)
    chunked, parts, done = make(), [], 0
    rng = np.random.default_rng(7)
    sizes = [1, 1, 2]
    while done < 3000:
        n = int(min(3000 - done, sizes.pop() if sizes else rng.integers(1, 700)))
        if 1000 <= done < 1700:                           # a few restores in another integrator
            state = chunked.state_arrays()
            chunked = make()
            chunked.restore(state)
        parts.append(chunked.advance(n))
        done += n
    for k, whole in enumerate((t, y, mode, events)):
        assert np.array_equal(np.concatenate([part[k] for part in parts]), whole)
    assert events.shape[0] > 20
    assert np.array_equal(one.y, chunked.y) and np.array_equal(one.fstate, chunked.fstate)
    assert one.counters == chunked.counters


def test_forces_of_a_single_row_equal_those_of_a_block():
    """The force columns of a block of one row (a resumed run's first block can be one row) are the bits of the
    same row computed in a block: BLAS' matrix-vector kernel sums in another order than its matrix kernel."""
    from app.case.schema import load_case
    from app.lumped.model import force_rows
    from app.lumped.outputs import contact_forces_N
    from app.lumped.parameters import derive_parameters

    p = derive_parameters(load_case(CASES / CASE).lumped)
    rows = force_rows(p)
    y = np.random.default_rng(3).standard_normal((64, rows.shape[1]))
    mode = np.full(64, 7)
    block = contact_forces_N(y, mode, rows)
    for i in range(64):
        assert np.array_equal(contact_forces_N(y[i:i + 1], mode[i:i + 1], rows), block[i:i + 1]), i


# ------------------------------------------------------------------ refused checkpoints
def _copy(one_go, tmp_path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(one_go[0], out)
    return out


def _pointer(out: Path) -> Path:
    return out / "checkpoint" / "checkpoint.json"


def _state(out: Path) -> Path:
    seq = json.loads(_pointer(out).read_text())["seq"]
    return out / "checkpoint" / f"state-{seq}.npz"


def _resume(out: Path, *extra):
    from app.runner import run_case

    return run_case(CASES / CASE, [*SETS, *extra], out, quiet=True, resume=True)


def _edit_pointer(out: Path, edit) -> None:
    meta = json.loads(_pointer(out).read_text())
    edit(meta)
    _pointer(out).write_text(json.dumps(meta))


def _drop_array(out: Path, name: str) -> None:
    with np.load(_state(out)) as npz:
        arrays = {k: npz[k] for k in npz.files if k != name}
    with open(_state(out), "wb") as fh:
        np.savez(fh, **arrays)


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="edits files of a serial run")
@pytest.mark.parametrize("damage, key, words", [
    (lambda out: _edit_pointer(out, lambda m: m.update(tier="fe")), "tier", "tier 'fe'"),
    (lambda out: _edit_pointer(out, lambda m: m["case"]["lumped"].update(downforce_N=3.0)), "lumped.downforce_N",
     "differs from the checkpointed run"),
    (lambda out: _edit_pointer(out, lambda m: m["engine"].update(intervals=1999)), "engine", "interval count"),
    (lambda out: _drop_array(out, "cflags"), "engine", "'cflags'"),
    (lambda out: _truncate(_state(out)), None, "truncated or corrupt"),
    (lambda out: _truncate(_pointer(out)), None, "not valid JSON"),
    (lambda out: (out / "transient.h5").unlink(), None, "is missing"),
], ids=["other-tier", "other-case", "record-vs-state", "array-missing", "state-truncated", "json-truncated",
        "series-missing"])
def test_damaged_or_foreign_checkpoint_is_refused(one_go, tmp_path, damage, key, words):
    out = _copy(one_go, tmp_path)
    damage(out)
    with pytest.raises(CaseError) as info:
        _resume(out)
    assert info.value.key == key and words in info.value.message, info.value.line()
    assert "\n" not in info.value.line()


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="edits files of a serial run")
def test_resume_before_the_checkpoint_time_is_refused(one_go, tmp_path):
    out = _copy(one_go, tmp_path)
    with pytest.raises(CaseError) as info:
        _resume(out, "lumped.duration_s=0.01")
    assert info.value.key == "lumped.duration_s" and "before the checkpoint" in info.value.message


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial and 2-rank subprocesses")
@pytest.mark.parametrize("mpi", [0, 2])
def test_cli_refusal_is_one_line_on_one_and_two_ranks(one_go, tmp_path, mpi):
    out = _copy(one_go, tmp_path)
    _truncate(_state(out))
    result = run_cli("run", CASES / CASE, "--resume", out, "--quiet", *_cli_sets(SETS), mpi=mpi)
    assert result.returncode == 2, result.stderr[-2000:]
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    if mpi:        # mpirun adds its own banner about the exit status; piezodyn's part is one line, rank 0's
        lines = [line for line in lines if "piezodyn" in line or "Traceback" in line or "Error" in line]
    assert len(lines) == 1 and lines[0].startswith("piezodyn: error: ") and "state-" in lines[0], result.stderr


# ------------------------------------------------------------------ kill anywhere, resume to the same bits
# PIEZODYN_KILL_AT=<event>:<n> SIGKILLs the run at the n-th <event> (app/killpoint.py). The run writes its
# series in ~56 blocks (one per 2 % of the run for the progress lines, cut at the checkpoints at rows 300,
# 600, ..., 1800 and 2000).
KILL_POINTS = [
    "series_block:1",          # the first block (with the row at t = 0) written, no checkpoint yet: start again
    "checkpoint_state:1",      # the first checkpoint's state written, its JSON not
    "checkpoint_tmp:1",        # half the first checkpoint JSON in its temporary file
    "series_block:20",         # between checkpoints: rows and events after the checkpoint are dropped
    "checkpoint_tmp:4",        # a later checkpoint half written
    "checkpoint_state:7",      # the final checkpoint's state (at the end) written, its JSON not
    "checkpoint_tmp:7",        # the final checkpoint half written
]
KILL_POINTS_FAST = ["series_block:20", "checkpoint_state:7"]


@pytest.fixture(scope="module")
def one_go_cli(tmp_path_factory):
    """The reference for the kill tests, in a fresh process like theirs."""
    out = tmp_path_factory.mktemp("lumped_one_go_cli")
    if MPI.COMM_WORLD.size == 1:
        result = run_cli("run", CASES / CASE, "--out", out, "--quiet", *_cli_sets(SETS))
        assert result.returncode == 0, result.stderr[-2000:]
    return out


def kill_and_resume(point: str, out: Path, reference: Path, mpi: int = 0) -> None:
    killed = run_cli("run", CASES / CASE, "--out", out, "--quiet", *_cli_sets(SETS), mpi=mpi, kill_at=point)
    assert killed.returncode != 0, f"{point}: the run was not killed"
    assert not (out / "summary.json").exists()
    if (out / "transient.h5").exists():                 # what a killed run leaves is readable
        data = read_time_series(out / "transient.h5")
        assert np.all(np.diff(data.get("time_s", np.zeros(0))) > 0)
    if point == "series_block:20":                      # the killed file holds rows the checkpoint does not
        meta = json.loads(_pointer(out).read_text())
        assert data["time_s"].size > meta["rows"] and data["events"].shape[0] > meta["loop"]["tables"]["events"]
    resumed = run_cli("run", CASES / CASE, "--resume", out, "--quiet", *_cli_sets(SETS), mpi=mpi)
    assert resumed.returncode == 0, f"{point}: " + resumed.stderr[-3000:]
    assert_identical(reference, out)
    summary, summary_ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    assert_same_results(summary_ref, summary)
    for name in summary["outputs"]:
        assert (out / name).is_file(), f"{point}: {name}"


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial subprocesses")
@pytest.mark.parametrize("point", KILL_POINTS_FAST)
def test_killed_anywhere_resumes_to_the_one_go_bits(one_go_cli, tmp_path, point):
    kill_and_resume(point, tmp_path, one_go_cli)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives 2-rank subprocesses")
@pytest.mark.parametrize("point", ["checkpoint_tmp:4"])
def test_killed_on_two_ranks_resumes_to_the_one_go_bits(one_go_cli, tmp_path, point):
    kill_and_resume(point, tmp_path, one_go_cli, mpi=2)


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial and 2-rank subprocesses")
@pytest.mark.parametrize("mpi", [0, 2])
@pytest.mark.parametrize("point", KILL_POINTS)
def test_killed_at_every_point_resumes_to_the_one_go_bits(one_go_cli, tmp_path, point, mpi):
    kill_and_resume(point, tmp_path, one_go_cli, mpi=mpi)


# ------------------------------------------------------------------ progress
PROGRESS = re.compile(r"^transient: +(\d+) % \| ([\d.]+)/([\d.]+) simulated ms \| wall \d\d:\d\d \| "
                      r"ETA (\d\d:\d\d|\?)$")


def _progress_lines(stderr: str) -> list[tuple[int, float, float]]:
    return [(int(m[1]), float(m[2]), float(m[3])) for m in map(PROGRESS.match, stderr.splitlines()) if m]


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives serial subprocesses")
def test_progress_lines_every_ten_percent_in_a_batch_log(tmp_path):
    """stderr to a pipe (not a terminal): one plain line per 10 % with simulated and wall time and ETA, for a
    fresh run and for a resumed one (counted from where it resumed)."""
    first = run_cli("run", CASES / CASE, "--out", tmp_path, *_cli_sets([*SETS[1:], "lumped.duration_s=0.005"]))
    assert first.returncode == 0, first.stderr[-2000:]
    lines = _progress_lines(first.stderr)
    assert [p for p, _, _ in lines] == list(range(10, 101, 10)), first.stderr
    assert [total for _, _, total in lines] == [5.0] * 10
    assert [done for _, done, _ in lines] == pytest.approx([0.5 * k for k in range(1, 11)])
    second = run_cli("run", CASES / CASE, "--resume", tmp_path, *_cli_sets(SETS))
    assert second.returncode == 0, second.stderr[-2000:]
    lines = _progress_lines(second.stderr)
    assert [p for p, _, _ in lines] == list(range(10, 101, 10)), second.stderr
    assert lines[-1][1:] == (15.0, 15.0)
    assert "\r" not in first.stderr + second.stderr
