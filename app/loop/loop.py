"""The one outer run loop of every transient engine (FE, modal, lumped).

Resume-or-start, the time-series writer, field output, checkpoints, the steady-state stop, progress lines and
the summary's common keys are done here once, for every tier. An engine implements the small protocol of
:class:`Engine`; inside :meth:`Engine.advance` it takes accepted steps in FESTIM's ``iterate()`` order
(update loads -> solve -> check convergence, cutting dt back on failure -> shift the state -> adapt dt), and
returns their time-series rows; the loop then exports (series, fields), checkpoints and tests the stop.

    (the runner holds the directory's lock) resume: read the checkpoint (every check before anything is touched)
    engine = make(found)                 build the model (a resumed modal run: its saved reduced model)
    found ? engine.restore(found) : (mark started, engine.start())
    while t < end and not steady:
        rows = engine.advance(end, steps to the next checkpoint, next field output (unless the engine takes
                              the frames itself: the modal kernel) or period end)
        steady.update_block(rows); series.write_block(rows since the last write) at each progress step;
        fields (buffered: those the engine took, a frame at t if due); progress
        checkpoint when due (the buffered field frames written first)
    checkpoint at the end; results = the common keys + engine.results()

A checkpoint is written after complete steps only (series flushed to the rows it names, the buffered field frames
written or, the modal tier's, carried in its record), so a run killed at any moment resumes to the same series,
bit for bit (tests/test_*_checkpoint.py kill it at every named point).
"""

from __future__ import annotations

import fcntl
import math
import os
import time
from pathlib import Path
from typing import Protocol

import numpy as np

from app import series as S
from app.errors import CaseError
from app.killpoint import kill_point
from app.loop.checkpoint import POINTER, CheckpointWriter, Found, case_digest, mark_started, read_checkpoint
from app.loop.steady import PERIOD_END_TOLERANCE, SteadyStateWatch
from app.progress import SimulatedTimeProgress
from app.series import TimeSeriesWriter

#: a field output is due at the first step with t >= next output time - this fraction of the interval
FIELD_TIME_TOLERANCE = 1e-9
LOCK_FILE = ".piezodyn.lock"


class Engine(Protocol):
    """What the loop needs of a transient engine (a tier's time integrator of one case).

    ``tier``: the case's tier; ``t``: the time of the current state [s]; ``steps``: accepted steps since
    t = 0 (a resumed run counts on); ``end_time_s``: the run's end; ``checkpoint_interval_steps``: a checkpoint
    every so many accepted steps (0: at the end only); ``case``: the case as the engine runs it (a drive locked to
    the model's resonance has its frequency resolved: app/drive.py locked_case)."""

    tier: str
    case: object
    t: float
    steps: int
    end_time_s: float
    checkpoint_interval_steps: int

    def start(self) -> None:
        """The initial state of a fresh run (rest, or the harmonic steady state)."""

    def restore(self, found: Found) -> None:
        """The state of a checkpoint (``found.arrays``, ``found.engine``)."""

    def columns(self) -> dict[str, str]:
        """Time-series column names and their units."""

    def advance(self, t_end: float, max_steps: int, stop_at_s: float) -> dict[str, np.ndarray]:
        """Accepted steps until ``t_end``, ``max_steps`` or the first step at or after ``stop_at_s``
        (whichever comes first); their rows (column -> array, one row per step)."""

    def take_tables(self) -> dict[str, tuple[str, np.ndarray]]:
        """Rows of the engine's tables since the last call (name -> (units, rows)): datasets of the series file
        whose rows are not the time rows (an event table, per-interval diagnostics)."""

    def snapshot(self) -> tuple[dict | None, dict]:
        """(state arrays: rank 0's are stored, JSON-able record) of the current state."""

    def checkpoint_files(self, out_dir: Path) -> dict[str, str]:
        """Files of its own the engine writes into the checkpoint directory once per run (key -> name)."""

    def field_export(self, out_dir: Path, resume_from_s: float | None):
        """An :class:`app.transient.fields.FieldSeriesExport`-like object (``write(t, z)``, ``flush()``, ``next_s``,
        ``interval_s``, ``close()``, ``files()``, ``path``, ``written``) or None (no FE fields)."""

    def body_positions(self) -> np.ndarray:
        """The rigid bodies' coordinates (packed), for the field export's body markers."""

    def results(self) -> dict:
        """The engine's own summary keys (counters, reduction, drive ...)."""

    def statistics(self, h5_path: Path) -> tuple[dict, dict]:
        """(per contact summary, generic statistics) of the finished run, from its time series (rank 0)."""

    def close(self) -> None:
        """Free solver objects."""


class DirectoryLock:
    """An exclusive lock on a result directory for the run's duration (rank 0 holds it): a second run or a
    ``--resume`` of a directory a live run is writing is refused before anything in it changes. Taken once per
    run, by its runner (app/runner.py:run_case), around every analysis it writes there."""

    def __init__(self, out_dir: Path, comm, flag: str):
        self.handle = None
        why = None
        if comm.rank == 0:
            try:
                self.handle = open(Path(out_dir) / LOCK_FILE, "a+")
                fcntl.flock(self.handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                self.handle.seek(0)
                self.handle.truncate()
                self.handle.write(f"{os.getpid()}\n")
                self.handle.flush()
            except BlockingIOError:
                why = "another piezodyn run is writing this directory now (its lock is held): wait for it to end"
            except OSError as exc:
                why = f"cannot be locked ({exc.strerror or exc})"
            if why and self.handle is not None:
                self.handle.close()
                self.handle = None
        why = comm.bcast(why, root=0) if comm.size > 1 else why
        if why:
            raise CaseError(flag, str(out_dir), why)

    def release(self) -> None:
        """Remove the lock file while holding the lock, then let go (a run killed before this leaves the file;
        the kernel has released its lock, so the next run takes it)."""
        if self.handle is not None:
            Path(self.handle.name).unlink(missing_ok=True)
            fcntl.flock(self.handle.fileno(), fcntl.LOCK_UN)
            self.handle.close()
            self.handle = None


def steady_state_watch(case, columns: dict[str, str], floors: tuple[float, float] = (0.0, 0.0)
                       ) -> SteadyStateWatch | None:
    """The watch of ``[transient.steady_state]`` (None without it): the body's first rotation, its speed if
    free, else the summed torque of the contacts on it. ``floors``: (speed [rad/s], torque [N m]) scales
    below which a change counts as noise (the case's keys, else the scene's defaults)."""
    cfg = case.transient.steady_state if case.transient is not None else None
    if cfg is None:
        return None
    body = next(b for b in case.transient.bodies if b.name == cfg.body)
    free = body.rotations[0].motion == "free"
    torques = [S.contact_torque(c.name) for c in case.transient.contacts
               if c.kind == "surface" and c.body == cfg.body and S.contact_torque(c.name) in columns]
    if not free and not torques:
        raise CaseError(case.source, "transient.steady_state.body",
                        f"the rotation of body {cfg.body!r} is prescribed and no surface contact acts on it: "
                        "no torque to watch")
    floor = cfg.speed_floor_rad_per_s if free else cfg.torque_floor_N_m
    if floor is None:
        floor = floors[0] if free else floors[1]
    return SteadyStateWatch(cfg.body, S.body_angular_velocity(cfg.body), torques, free,
                            case.transient.drive.frequency_Hz, cfg.window_cycles, cfg.relative_tolerance,
                            cfg.min_cycles, floor, cfg.rule)


def run_transient(make_engine, case, out_dir: Path, comm, log, resume: bool = False,
                  steady_floors: tuple[float, float] = (0.0, 0.0)) -> dict:
    """Run a transient case with the engine ``make_engine(found)`` builds (``found``: the checkpoint to resume
    from, or None) into ``out_dir``; with ``resume`` continue from the checkpoint there (same case except the
    end time, the checkpoint interval and the outputs) and append to its series. Returns the summary's
    transient results (common keys, the engine's, per-contact summaries and statistics). The caller holds the
    directory's :class:`DirectoryLock` (app/runner.py:run_case)."""
    out_dir = Path(out_dir)
    setup_start = time.perf_counter()
    digest = case_digest(case)
    found = read_checkpoint(out_dir, comm, case, digest, case.tier) if resume else None
    engine = make_engine(found)
    case = engine.case      # the case as the engine runs it (a drive locked to the resonance: its frequency resolved)
    if found is not None:
        engine.restore(found)
        log(f"{engine.tier} tier: resuming at t = {engine.t * 1e3:.6g} ms from {out_dir / 'checkpoint'} "
            f"({found.rows} time-series rows kept)")
        files, seq = found.record.get("files") or {}, found.seq
    else:
        if resume:
            log(f"{engine.tier} tier: {out_dir} holds a run killed before its first checkpoint: starting it again")
        mark_started(out_dir, comm, digest)
        engine.start()
        files, seq = engine.checkpoint_files(out_dir), 0
    t_start = engine.t
    columns = engine.columns()
    h5_path = out_dir / S.TIME_SERIES_FILE
    series = TimeSeriesWriter(h5_path, columns, comm, resume_rows=found.rows if found is not None else None,
                              resume_tables=found.loop.get("tables") if found is not None else None)
    checkpoint = CheckpointWriter(out_dir, comm, engine.checkpoint_interval_steps, engine.tier, digest, seq=seq,
                                  files=files)
    watch = steady_state_watch(case, columns, steady_floors)
    if watch is not None and found is not None and found.loop.get("steady_state") is not None:
        watch.restore(found.loop["steady_state"])
    fields = engine.field_export(out_dir, t_start if found is not None else None)
    if fields is not None and found is not None and hasattr(fields, "resume"):
        fields.resume(found.loop.get("fields"), found.arrays)     # the frames the checkpoint buffered, again
    if fields is not None and found is None:
        fields.write(engine.t, engine.body_positions())
    end = engine.end_time_s
    period = 1.0 / case.transient.drive.frequency_Hz if watch is not None else None
    progress = SimulatedTimeProgress(comm, t_start, end)
    progress_step = max(end - t_start, 0.0) / 50
    setup_wall = time.perf_counter() - setup_start
    start, start_cpu = time.perf_counter(), time.process_time()
    field_wall = checkpoint_wall = field_cpu = 0.0
    steady = watch is not None and watch.steady
    # a resumed run's state is its checkpoint's: nothing to write again unless it takes a step
    checkpointed = engine.steps if found is not None else -1
    unwritten: list[dict] = []          # row blocks of the engine not yet in the series file
    series_due = t_start + progress_step
    try:
        while engine.t < end * (1 - 1e-12) and not steady:
            stop_at = math.inf
            if fields is not None and getattr(fields, "engine_frames", None) is None:    # else the engine takes them
                stop_at = fields.next_s - FIELD_TIME_TOLERANCE * fields.interval_s
            if period is not None:       # the steady test runs at period ends: stop there
                stop_at = min(stop_at, (math.floor(engine.t / period + PERIOD_END_TOLERANCE) + 1 - PERIOD_END_TOLERANCE)
                              * period)
            stop_at = min(stop_at, engine.t + progress_step)     # progress lines on time
            rows = engine.advance(end, checkpoint.steps_to_next(engine.steps), stop_at)
            if rows and len(rows[S.TIME]):
                unwritten.append(rows)
                if watch is not None:
                    steady = watch.update_block(rows, getattr(engine, "period_state", None))
            # a stop for a field frame only: its rows go to the file with the next block (an HDF5 append costs
            # milliseconds, a frame burst stops the engine every few steps); a checkpoint writes them first
            if unwritten and (engine.t >= series_due - 1e-9 * progress_step or checkpoint.due(engine.steps) or steady
                              or engine.t >= end * (1 - 1e-12)):
                _write_rows(series, unwritten)
                series_due = engine.t + progress_step
                kill_point("series_block")
            for name, (units, table) in engine.take_tables().items():
                series.append_table(name, table, units)
            if fields is not None:           # the frames the engine took; a frame at t when one is due
                field_wall, field_cpu = _timed(lambda: fields.write(engine.t, engine.body_positions()),
                                               field_wall, field_cpu)
            progress.update(engine.t)
            if checkpoint.due(engine.steps) or steady:
                field_wall, field_cpu = _flush(fields, field_wall, field_cpu, before_checkpoint=True)
                mark = time.perf_counter()
                checkpointed = _checkpoint(engine, checkpoint, series, watch, fields)
                checkpoint_wall += time.perf_counter() - mark
        _write_rows(series, unwritten)
        if checkpointed != engine.steps:
            field_wall, field_cpu = _flush(fields, field_wall, field_cpu)
            mark = time.perf_counter()
            _checkpoint(engine, checkpoint, series, watch, fields)
            checkpoint_wall += time.perf_counter() - mark
        field_wall, field_cpu = _flush(fields, field_wall, field_cpu)
    finally:
        progress.close()
        _write_rows(series, unwritten)          # a failed step: the rows of the steps before it
        series.close()
        if fields is not None:           # waits for the field output's writer thread, if it has one
            field_wall, field_cpu = _timed(fields.close, field_wall, field_cpu)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    writer_cpu, writer_wall = getattr(fields, "writer_cpu_s", 0.0), getattr(fields, "writer_wall_s", 0.0)
    simulated = engine.t - t_start
    results = {"tier": engine.tier, "steps": engine.steps, "simulated_time_s": engine.t,
               "resumed_from_s": t_start if found is not None else None,
               "wall_time_s": wall, "cpu_time_s": cpu, "setup_wall_s": setup_wall,
               "wall_s_per_simulated_ms": wall / (simulated * 1e3) if simulated > 0 else None,
               "time_series": h5_path.name, "checkpoint": f"{checkpoint.dir.name}/{POINTER}",
               "checkpoints_written": checkpoint.written, "checkpoint_wall_s": checkpoint_wall,
               "fields": fields.path.name if fields is not None else None,
               "field_outputs": fields.written if fields is not None else 0, "field_output_wall_s": field_wall,
               "field_output_cpu_s": field_cpu + writer_cpu, "field_writer_wall_s": writer_wall,
               "field_writer_cpu_s": writer_cpu}
    if getattr(fields, "peaks", None):      # peaks per region of the derived fields over the frames (app.fe.derived)
        results["field_peaks"] = fields.peaks
    if getattr(getattr(fields, "vertex", None), "region_names", None):    # tag -> name of the files' region tags
        results["regions"] = {str(tag): name for tag, name in sorted(fields.vertex.region_names.items())}
    results.update(engine.results())
    if watch is not None:
        results["steady_state"] = watch.results()
        log(f"{engine.tier} tier: {'steady' if watch.steady else 'not steady'} after {len(watch.means)} periods")
    summaries = engine.statistics(h5_path) if comm.rank == 0 else None
    results["contacts"], results["statistics"] = comm.bcast(summaries, root=0)
    results["outputs"] = [h5_path.name, *checkpoint.files(), *(fields.files() if fields is not None else [])]
    if case.output.series_csv:                   # the whole series (a resumed run's too), once at the end
        if comm.rank == 0:
            S.write_series_csv(h5_path, out_dir / S.SERIES_CSV)
        results["outputs"].append(S.SERIES_CSV)
    engine.close()
    return results


def _write_rows(series: TimeSeriesWriter, blocks: list[dict]) -> None:
    """Append the engine's row blocks to the series file as one block, and empty ``blocks``."""
    if not blocks:
        return
    block = blocks[0] if len(blocks) == 1 else {name: np.concatenate([b[name] for b in blocks]) for name in blocks[0]}
    blocks.clear()
    series.write_block(block)


def _flush(fields, wall: float, cpu: float, before_checkpoint: bool = False) -> tuple[float, float]:
    """Write the field frames the export buffers (app/transient/fields.py): before every checkpoint, so each frame
    at or before the checkpoint's time is on disk when the checkpoint is (a resumed run writes only the later
    ones again), unless the buffer rides in the checkpoint (``carries``: the modal tier's frames, a few
    coordinates each); and at the end. Returns the field output's wall and CPU time [s] with this flush's."""
    if fields is None or (before_checkpoint and getattr(fields, "carries", False)):
        return wall, cpu
    return _timed(fields.flush, wall, cpu)


def _timed(call, wall: float, cpu: float) -> tuple[float, float]:
    """Run ``call`` and add its wall and CPU time [s] to ``wall`` and ``cpu``: this thread's CPU only (the field
    output's writer thread counts its own, app/transient/fields.py)."""
    mark, mark_cpu = time.perf_counter(), time.thread_time()
    call()
    return wall + time.perf_counter() - mark, cpu + time.thread_time() - mark_cpu


def _checkpoint(engine, checkpoint: CheckpointWriter, series: TimeSeriesWriter, watch, fields=None) -> int:
    """Write a checkpoint of the engine's state after complete steps; returns the step count it holds."""
    series.flush()
    arrays, record = engine.snapshot()
    loop = {"steady_state": watch.snapshot() if watch is not None else None, "tables": dict(series.table_rows)}
    if fields is not None and hasattr(fields, "checkpoint_record"):
        loop["fields"], field_arrays = fields.checkpoint_record()
        if arrays is not None:
            arrays = {**arrays, **field_arrays}
    checkpoint.write(engine.t, arrays, record, loop, series.rows_written)
    return engine.steps
