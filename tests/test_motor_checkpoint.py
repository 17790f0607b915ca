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
periods before the checkpoint, and the summary's window spans it. One more split falls within an output interval
(6.5 periods): the per-site tables' open sums, wave-frame bins and wave phases travel in the checkpoint.
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
            "checkpoint_wall_s", "stepping_wall_time_s", "field_output_wall_s", "cpu_time_s", "field_output_cpu_s",
            "field_writer_wall_s", "field_writer_cpu_s"}
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
    for name in ("motor_ring.csv", "motor_contact_path.csv", "motor_wave_frame.csv"):
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


def test_motor_resume_within_an_output_interval_equals_one_run(one_go, tmp_path):
    """Split at 6.5 periods, halfway through a per-site table's interval (one period): the checkpoint carries the
    interval's open sums, its wave-frame bins and the sites' wave phases (app/contact/tables.py), so the resumed run
    is the one-go run bit for bit (the splits above fall on the intervals' ends, where the sums are empty)."""
    from app.runner import run_case

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")
    first = run_case_quiet(CASE, tmp_path, *SETS, f"transient.end_time_s={HALF_S * 13 / 12!r}")
    assert not first["results"]["transient"]["steady_state"]["steady"]
    run_case(CASE, SETS, tmp_path, quiet=True, resume=True)
    assert_same_run(one_go, tmp_path)


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


# ------------------------------------------------------------------ the trend rule and warm starts
@pytest.mark.mpi
@pytest.mark.parametrize("rule", ["trend", "orbit"])
def test_motor_steady_rule_resume_equals_one_run(shared_tmp, rule):
    """The trend and orbit steady-state rules (app/loop/steady.py) decide from the cycle means the checkpoint holds:
    a run split at 6 periods and resumed equals the run in one go bit for bit, its last fit included (fitted over
    periods on both sides of the split). In 12 periods the rotor is still spinning up (cycle means 0.05 to 3.4
    rad/s), which the window rule at SETS' loose tolerance takes for steady at period 10 and the trend rule does
    not: the fit's change still to come exceeds the tolerance (measured: 5 to 28 times the means' scale). The stop
    decision after a restore is checked on the watch itself (tests/test_steady_rules.py). The orbit rule adds the
    stator's state at each period end: the checkpoint holds the last one, so the resumed run's relative returns
    (every period's, known from the first closed one on) equal the run's in one go."""
    comm = MPI.COMM_WORLD
    trend = SETS + [f'transient.steady_state.rule="{rule}"']
    whole = shared_tmp / "whole"
    res = run_case_quiet(CASE, whole, *trend)["results"]["transient"]["steady_state"]
    assert res["rule"] == rule and not res["steady"] and res["cycles"] == 11
    assert len(res["period_returns"]) == 11 and all(r is not None and r > 0 for r in res["period_returns"])
    fitted = res["cycle_means"][-res["trend"]["fit_periods"]:]
    assert res["trend"]["remaining"] > 0.8 * max(abs(m) for m in fitted)
    split = shared_tmp / "split"
    run_case_quiet(CASE, split, *trend, f"transient.end_time_s={HALF_S!r}")
    from app.runner import run_case

    run_case(CASE, trend, split, quiet=True, resume=True)
    comm.barrier()
    if comm.rank == 0:
        assert_same_run(whole, split)


def _series_rows(out: Path) -> dict:
    series = read_series(out / "transient.h5")
    rows = series["time_s"].size
    return {k: v for k, v in series.items() if v.shape[:1] == (rows,)}


def test_motor_warm_start_continues_the_state_it_starts_from(one_go, tmp_path):
    """``transient.start_from`` (a warm start): a run of 6 periods, then a second run of the case that starts from
    its end state, take the same steps as the run in one go from period 6 on: every state column (stator samples,
    electrode charges, rotor, contact forces) agrees with it to 1e-9 relative (measured 3e-11: the clock moved back
    by 6 periods carries a round-off of 1e-18 s into the drive's phase). The warm run's own clock starts at 0 and
    its energy sums (dissipation since the start) start from zero; its drive stays the source run's cosine (a
    harmonic start) although this case says "rest". Its summary names the source. And a warm run split and
    resumed equals it in one go (the warm start is read once, at the start; the checkpoint holds the rest)."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")
    source = tmp_path / "source"
    run_case_quiet(CASE, source, *SETS, f"transient.end_time_s={HALF_S!r}")
    warm_sets = SETS + [f"transient.start_from={str(source)!r}", 'transient.initial_state="rest"']
    warm = tmp_path / "warm"
    res = run_case_quiet(CASE, warm, *warm_sets)["results"]["transient"]
    assert res["warm_start"]["directory"] == str(source)
    assert res["warm_start"]["source_time_s"] == pytest.approx(HALF_S, rel=1e-12)
    assert 0 <= res["warm_start"]["start_time_s"] < 1e-12
    whole, rows = _series_rows(one_go), _series_rows(warm)
    offset = 240                                      # 6 periods of 40 steps
    n = min(rows["time_s"].size, whole["time_s"].size - offset)
    assert n >= 120
    np.testing.assert_allclose(rows["time_s"][:n] + HALF_S, whole["time_s"][offset:offset + n], rtol=1e-12)
    energies = {"damping_dissipated_J", "stator_rotor_dissipated_J", "time_s", "dt_s"}
    for name in sorted(set(rows) & set(whole) - energies):
        reference = whole[name][offset:offset + n]
        scale = np.max(np.abs(reference)) or 1.0
        np.testing.assert_allclose(rows[name][:n] / scale, reference / scale, rtol=0, atol=1e-9, err_msg=name)
    # dissipation counts from the warm run's start
    assert rows["damping_dissipated_J"][0] < 0.1 * whole["damping_dissipated_J"][offset]

    split = tmp_path / "warm_split"
    run_case_quiet(CASE, split, *warm_sets, f"transient.end_time_s={3 / 36065.0!r}")
    from app.runner import run_case

    run_case(CASE, warm_sets, split, quiet=True, resume=True)
    assert_same_run(warm, split)


def test_motor_warm_start_at_another_frequency_keeps_the_drive_phase(tmp_path):
    """A warm start at another drive frequency (a frequency sweep, bench/bench_motor_frequency.py) starts where the
    new drive's phase equals the source drive's phase at the source's end, as a swept generator's phase is
    continuous: (start time x new frequency) and (source end time x source frequency) agree modulo one cycle, to
    1e-9 cycles (the round-off of a few products of 1e-4 s and 4e4 Hz). Physically: the drive voltage of the
    warm run's first step differs from the source's last by at most one step of the sine (2 pi / 40 of the
    amplitude, x 1.1); the frequencies here differ by 1.5 kHz over 6.3 periods, so a clock moved back by whole
    periods of the new frequency alone would jump the phase by 0.26 cycles (a 1.6 rad kick of the drive). The
    drive is locked to the reduced model's resonance (app/drive.py) so the detuning changes no basis."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")
    locked = SETS + ['transient.drive.lock="resonance"', "transient.drive.lock_modes=2"]
    source = tmp_path / "source"
    source_s = 6.3 / 36065.0
    res0 = run_case_quiet(CASE, source, *locked, f"transient.end_time_s={source_s!r}")["results"]["transient"]
    warm = tmp_path / "warm"
    res = run_case_quiet(CASE, warm, *locked, "transient.drive.detuning_Hz=1500.0",
                         f"transient.start_from={str(source)!r}", f"transient.end_time_s={1 / 36065.0!r}",
                         )["results"]["transient"]
    f0, f1 = res0["drive"]["frequency_Hz"], res["drive"]["frequency_Hz"]
    assert f1 - f0 == pytest.approx(1500.0, rel=1e-9)
    record = res["warm_start"]
    assert record["source_frequency_Hz"] == f0 and record["frequency_Hz"] == f1
    source_cycles = record["source_time_s"] * f0
    start_cycles = record["start_time_s"] * f1
    assert (start_cycles - source_cycles + 0.5) % 1.0 - 0.5 == pytest.approx(0.0, abs=1e-9)
    assert abs(source_s * (f1 - f0) % 1.0 - 0.5) < 0.4       # the test's premise: a whole-period move would jump
    a, b = _series_rows(source), _series_rows(warm)
    amplitude = np.max(np.abs(a["drive_voltage_V"]))
    assert abs(b["drive_voltage_V"][0] - a["drive_voltage_V"][-1]) <= 1.1 * 2 * np.pi / 40 * amplitude


def test_motor_warm_start_errors_are_one_line(capsys, one_go, tmp_path):
    """A warm start from a directory that is missing, holds no checkpoint, or a run of another reduced model: exit
    2, one line naming the case file and transient.start_from (validate and run alike where validate can tell)."""
    from test_bad_input_suite import assert_one_line, cli_main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial")

    def run(command, source, *more):
        flags = ("--out", tmp_path / "out", "--quiet") if command == "run" else ()
        return cli_main(capsys, command, CASE, *flags,
                        *_cli_sets(SETS + [f"transient.start_from={str(source)!r}", *more]))

    for command in ("validate", "run"):
        assert_one_line(*run(command, tmp_path / "absent"), CASE, "transient.start_from", "not a directory")
        empty = tmp_path / "empty"
        empty.mkdir(exist_ok=True)
        assert_one_line(*run(command, empty), CASE, "transient.start_from", "no checkpoint")
    # a run of another reduced model (its stiffness changed by 1e-6: a stator that is not this case's)
    from app.reduced.model import ReducedModel

    other = tmp_path / "other"
    shutil.copytree(one_go, other)
    path = other / "checkpoint" / "reduced-model.npz"
    model = ReducedModel.load(path)
    model.K = model.K * (1 + 1e-6)
    with open(path, "wb") as fh:
        model.save(fh)
    assert_one_line(*run("run", other), CASE, "transient.start_from", "another reduced model")
