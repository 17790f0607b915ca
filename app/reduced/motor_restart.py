"""Checkpoints and ``--resume`` of the motor in the modal tier (app/reduced/motor.py).

The files are the drill's (app/reduced/restart.py, app/loop/checkpoint.py): in ``DIR/checkpoint/``,
``run.json`` (the case, written when a fresh run starts), ``reduced-model.npz`` (written once),
``state-<seq>.npz`` and ``checkpoint.json`` naming it (rank 0, temporary file, fsync, rename, the JSON last).
A run killed at any moment leaves the previous checkpoint or the new one, and a time series with at least the
rows the checkpoint names; the resumed run drops the rows after them.

The reduced stator is part of the checkpoint: the cache it came from (``PIEZODYN_CACHE_DIR``) may be gone or
rebuilt by then, and a rebuilt reduction differs in round-off (eigensolver; on other ranks, the partition), in
which the saved modal coordinates would mean something slightly different. So a resumed run reads the very
arrays (K, M, C, charge rows, band nodes) the interrupted one ran with, and every other array of the loop
follows from them and the case (deterministically).

What the state file holds (the loop's complete state at the end of a drive period; checkpoints fall on period
ends, every ``round(transient.checkpoint_interval_steps / steps per period)`` periods, at least one, and at the
end of the run): the stator coordinates q, v, a; the rotor's dz, dz', dz'', angle, spin and spin rate (``rot``);
the cumulative energies and the integer counters the compiled loop carries between its calls; the time; the
number of periods; the steady-state watch's cycle means and verdict; and the summary's window: the last
``window_cycles`` periods' output rows, contact-point states and normal forces, the contact point's path and the
row before each period (the energy differences start there). The compiled loop recomputes everything else at the
start of each call from these, so a resumed run repeats the interrupted one's periods bit for bit and its
summary is the one-go run's.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from app.errors import CaseError
from app.files import atomic_write
from app.loop.checkpoint import (  # noqa: F401 (mark_started: the motor's entry point)
    CHECKPOINT_DIR,
    CheckpointWriter,
    case_digest,
    mark_started,
    read_checkpoint,
    read_on_root,
)
from app.reduced.restart import MODEL_FILE, MODEL_KEY

#: the arrays of a state file (see the module docstring); the history_* arrays are stacked per period
STATE_ARRAYS = ("q", "v", "a", "rot", "energies", "istate", "t_s", "periods", "steady", "steady_means", "last_row",
                "history_columns", "history_point_state", "history_point_fn", "history_trajectory",
                "history_before")


def write_ring(fh, ring) -> None:
    """The reduced stator (a :class:`app.reduced.motor.RingModel`) as npz into the open file ``fh``: every field
    under its own name (the motor cache's files and the checkpoint's reduced-model.npz)."""
    arrays = {f.name: np.asarray(getattr(ring, f.name)) for f in dataclasses.fields(ring)}
    arrays["electrodes"] = np.array(ring.electrodes, dtype=str)
    np.savez(fh, **arrays)


def read_ring(path: Path, cls):
    """The ``cls`` (RingModel) stored in ``path`` by :func:`write_ring`. Raises KeyError (a field missing: another
    version), OSError, ValueError, EOFError or zipfile.BadZipFile (unreadable)."""
    values = {}
    with np.load(path, allow_pickle=False) as f:
        for field in dataclasses.fields(cls):
            value = f[field.name]
            if field.name == "electrodes":
                values[field.name] = [str(e) for e in value]
            else:
                values[field.name] = value.item() if value.ndim == 0 else np.array(value)
    return cls(**values)


def run_digest(case, warm_start) -> dict:
    """The record a resumed run must match: the case (app.loop.checkpoint.case_digest) and, for a run
    continued from another run's end state (``warm_start``, the benches' API), that file: a run killed before its
    first checkpoint starts again from it, not from the case's initial state."""
    digest = case_digest(case)
    if warm_start is not None:
        digest["warm_start"] = str(Path(warm_start).resolve())
    return digest


def find(out_dir: Path, comm, case, digest: dict, cls):
    """Collective. (record, state arrays, RingModel) of the checkpoint in ``out_dir``, or None when the run there
    was killed before its first checkpoint (start it again). One-line CaseError (exit 2) when there is no
    checkpoint, it or its reduced model is unreadable, or it belongs to another case (naming the key)."""
    found = read_checkpoint(out_dir, comm, case, digest, needs=(MODEL_KEY,))
    if found is None:
        return None
    meta, data = found
    missing = [k for k in STATE_ARRAYS if k not in data]
    pointer = Path(out_dir) / CHECKPOINT_DIR / "checkpoint.json"
    if missing:
        raise CaseError(str(pointer), "seq", f"the state file state-{meta['seq']}.npz has no {missing[0]!r} "
                                             "(not a motor checkpoint of this version)")
    path = Path(out_dir) / CHECKPOINT_DIR / str(meta[MODEL_KEY])
    return meta, data, read_on_root(path, comm, lambda p: read_ring(p, cls), "a motor's reduced stator")


def save_ring(out_dir: Path, comm, ring) -> None:
    """Collective: store the reduced stator of a fresh run in its checkpoint directory (once; after
    app.loop.checkpoint.mark_started: killed before it is complete, the run is one killed before its first
    checkpoint, which --resume starts again)."""
    if comm.rank == 0:
        atomic_write(Path(out_dir) / CHECKPOINT_DIR / MODEL_FILE, lambda fh: write_ring(fh, ring), sync=True)
    comm.barrier()


def writer(out_dir: Path, comm, digest: dict, drive_V: float, seq: int) -> CheckpointWriter:
    return CheckpointWriter(out_dir, None, 0, drive_V, digest, seq=seq, comm=comm)


def interval_periods(interval_steps: int, steps_per_period: int) -> int:
    """``transient.checkpoint_interval_steps`` in whole drive periods (the loop's calls): the nearest number, at
    least one; 0 (checkpoints at the end only) stays 0."""
    if interval_steps <= 0:
        return 0
    return max(1, int(round(interval_steps / steps_per_period)))


def state_arrays(q, v, a, rot, energies, istate, t_s: float, periods: int, steady: bool, steady_means: list,
                 last_row, history: list) -> dict:
    """The state file's arrays (rank 0 writes them). ``history``: per period (columns, point_state, point_fn,
    trajectory, the row before it), as app.reduced.motor.run keeps them; the contact-point states (0..3) as int8."""
    return {"q": q, "v": v, "a": a, "rot": rot, "energies": energies, "istate": istate, "t_s": np.array(t_s),
            "periods": np.array(periods), "steady": np.array(steady), "steady_means": np.array(steady_means, float),
            "last_row": last_row,
            "history_columns": np.stack([h[0] for h in history]),
            "history_point_state": np.stack([h[1] for h in history]).astype(np.int8),
            "history_point_fn": np.stack([h[2] for h in history]),
            "history_trajectory": np.stack([h[3] for h in history]),
            "history_before": np.stack([h[4] for h in history])}


def history_of(data: dict) -> list:
    """The per-period history of a state file, as app.reduced.motor.run keeps it."""
    return [(data["history_columns"][k].copy(), data["history_point_state"][k].astype(np.int64),
             data["history_point_fn"][k].copy(), data["history_trajectory"][k].copy(),
             data["history_before"][k].copy()) for k in range(data["history_columns"].shape[0])]


def checkpoint_files(out_dir: Path, checkpoint: CheckpointWriter) -> list[str]:
    """The checkpoint's files on disk, relative to the output directory (for the summary's outputs)."""
    names = checkpoint.files() + [f"{CHECKPOINT_DIR}/{MODEL_FILE}"]
    return [name for name in names if (Path(out_dir) / name).is_file()]
