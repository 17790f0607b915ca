"""Checkpoints of a transient run, and resuming from them.

A checkpoint holds everything needed to continue a run bit-identically: the FE displacement,
velocity and acceleration (local arrays incl. ghosts, one file per MPI rank), the rigid-body
states, t, the step controller (cap after cut-backs, counters), whether the last step changed the
contact set (the next dt depends on it), the run statistics, the drive voltage and the number of
HDF5 time-series rows written. The contact state itself (which contacts are closed) is a function
of the saved fields, so it is recomputed.

Layout in ``DIR/checkpoint/``: ``state-<seq>-rank<r>.npz`` per rank and ``checkpoint.json``
(written by rank 0 last, through a temporary file and a rename). The JSON names the ``seq`` of a
complete set of rank files, so a run killed at any moment leaves either the previous or the new
checkpoint, never a mix. Older rank files are removed after the JSON points past them.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.errors import CaseError
from app.transient.state import TransientState

CHECKPOINT_DIR = "checkpoint"
POINTER = "checkpoint.json"
FORMAT = 1


@dataclass
class Resumed:
    """What a run continues from: the state, the stepper snapshot (controller, statistics, last
    contact change), the drive voltage [V], the number of time-series rows to keep and the
    checkpoint's sequence number."""

    state: TransientState
    stepper: dict
    voltage_V: float
    rows: int
    seq: int


class CheckpointWriter:
    """``write(state, stepper_snapshot, rows)`` every ``interval_steps`` accepted steps (``due``) and
    at the end of a run. ``flush`` is called first so that the time series on disk has exactly
    ``rows`` rows when the checkpoint names them."""

    def __init__(self, out_dir: Path, comm, interval_steps: int, voltage_V: float, case_digest: dict,
                 flush=None, seq: int = 0):
        self.dir = Path(out_dir) / CHECKPOINT_DIR
        self.comm = comm
        self.interval_steps = int(interval_steps)
        self.voltage_V = float(voltage_V)
        self.case_digest = case_digest
        self.flush = flush
        self.seq = seq
        self.written = 0
        if comm.rank == 0:
            self.dir.mkdir(parents=True, exist_ok=True)
        comm.barrier()

    def due(self, steps: int) -> bool:
        return self.interval_steps > 0 and steps % self.interval_steps == 0

    def _rank_file(self, seq: int, rank: int) -> Path:
        return self.dir / f"state-{seq}-rank{rank}.npz"

    def write(self, state: TransientState, stepper: dict, rows_of=None) -> None:
        """Collective. ``rows_of()`` returns the number of time-series rows on disk (after flush)."""
        if self.flush is not None:
            self.flush()
        rows = int(rows_of()) if rows_of is not None else 0
        rows = self.comm.bcast(rows, root=0)
        seq = self.seq + 1
        path = self._rank_file(seq, self.comm.rank)
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as fh:
            np.savez(fh, u=state.u, v=state.v, a=state.a, z=state.z, zd=state.zd, zdd=state.zdd)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        local_sizes = self.comm.gather(int(state.u.size), root=0)
        self.comm.barrier()                                  # every rank file is complete
        if self.comm.rank == 0:
            meta = {"format": FORMAT, "seq": seq, "t_s": state.t, "mpi_size": self.comm.size,
                    "local_sizes": local_sizes, "rows": rows, "voltage_V": self.voltage_V,
                    "stepper": stepper, "case": self.case_digest}
            pointer = self.dir / POINTER
            tmp = pointer.with_name(POINTER + ".tmp")
            with open(tmp, "w") as fh:
                json.dump(meta, fh, indent=1)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, pointer)
        self.comm.barrier()                                  # the pointer names seq now
        old = self._rank_file(self.seq, self.comm.rank)
        if self.seq and old.exists():
            old.unlink()
        self.seq = seq
        self.written += 1


def case_digest(case) -> dict:
    """The parts of the resolved case a resumed run must share with the checkpointed one (all of it
    except the end time, the checkpoint interval and the output options)."""
    from app.case.validate import to_dict

    data = json.loads(json.dumps(to_dict(case), default=str))
    data.pop("output", None)
    data.pop("source", None)
    transient = data.get("transient", {})
    for key in ("end_time_s", "checkpoint_interval_steps"):
        transient.pop(key, None)
    return data


def _differences(a, b, prefix="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for key in sorted(set(a) | set(b)):
            out += _differences(a.get(key), b.get(key), f"{prefix}.{key}" if prefix else key)
        return out
    return [] if a == b else [prefix]


def load_checkpoint(out_dir: Path, comm, case, digest: dict, local_size: int) -> Resumed:
    """Read the checkpoint of ``out_dir`` on every rank; CaseError (exit 2) when there is none or it
    does not belong to this case / MPI size / mesh partition."""
    file = case.source
    directory = Path(out_dir) / CHECKPOINT_DIR
    pointer = directory / POINTER
    meta = None
    if comm.rank == 0 and pointer.exists():
        meta = json.loads(pointer.read_text())
    meta = comm.bcast(meta, root=0)
    if meta is None:
        raise CaseError(str(out_dir), "--resume", f"no checkpoint in {out_dir} (expected {pointer})")
    if meta.get("format") != FORMAT:
        raise CaseError(str(pointer), "format", f"unknown checkpoint format {meta.get('format')!r}")
    if meta["mpi_size"] != comm.size:
        raise CaseError(str(pointer), "mpi_size",
                        f"checkpoint was written by {meta['mpi_size']} MPI rank(s); resume with the same number "
                        f"(this run has {comm.size})")
    changed = _differences(meta["case"], digest)
    if changed:
        raise CaseError(file, changed[0], "differs from the checkpointed run (only transient.end_time_s, "
                                          "transient.checkpoint_interval_steps and output.* may change on resume)")
    if meta["local_sizes"][comm.rank] != local_size:
        raise CaseError(str(pointer), "local_sizes", "the mesh partition differs from the checkpointed run")
    with np.load(directory / f"state-{meta['seq']}-rank{comm.rank}.npz") as data:
        state = TransientState(float(meta["t_s"]), *(np.array(data[k]) for k in ("u", "v", "a", "z", "zd", "zdd")))
    return Resumed(state, meta["stepper"], float(meta["voltage_V"]), int(meta["rows"]), int(meta["seq"]))
