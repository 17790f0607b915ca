"""Checkpoints of a transient run, and resuming from them.

A checkpoint holds everything needed to continue a run bit-identically: the FE displacement,
velocity and acceleration, the rigid-body states, t, the step controller (cap after cut-backs,
counters), whether the last step changed the contact set (the next dt depends on it), the run
statistics, the drive voltage and the number of HDF5 time-series rows written. The contact state
itself (which contacts are closed) is a function of the saved fields, so it is recomputed.

FE fields are stored per cell, keyed by the mesh's original (input) cell index: row c holds the
values of the DOFs of input cell c in the element's DOF order. That layout does not depend on the
MPI partition (which is not reproducible from run to run on several ranks), so a run can resume
on any number of ranks; on the same single rank it continues bit-identically.

Layout in ``DIR/checkpoint/``: ``state-<seq>.npz`` and ``checkpoint.json``, both written by rank 0
through a temporary file, fsync and a rename, the JSON last. The JSON names the ``seq`` of a
complete state file, so a run killed at any moment leaves either the previous or the new
checkpoint, never a mix. The older state file is removed after the JSON points past it.

A fresh run first writes ``run.json`` (the case digest) and removes any older checkpoint, so a run
killed before its first checkpoint (e.g. during the harmonic start) is known: ``--resume`` then
starts it again from t = 0 instead of refusing.
"""

from __future__ import annotations

import dataclasses
import json
import typing
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.errors import CaseError
from app.files import atomic_write, json_bytes, jsonable, write_json_atomic
from app.killpoint import kill_point
from app.transient.state import TransientState

CHECKPOINT_DIR = "checkpoint"
POINTER = "checkpoint.json"
MARKER = "run.json"
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

    def __init__(self, out_dir: Path, layout: CellLayout | None, interval_steps: int, voltage_V: float,
                 case_digest: dict, flush=None, seq: int = 0, comm=None):
        self.dir = Path(out_dir) / CHECKPOINT_DIR
        self.layout = layout        # None: no FE fields (the motor's modal tier): ``comm`` then, write_arrays only
        self.comm = comm = layout.comm if layout is not None else comm
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

    def files(self) -> list[str]:
        """The checkpoint's files, relative to the output directory."""
        names = [MARKER, POINTER] + ([self._state_file(self.seq).name] if self.seq else [])
        return [f"{CHECKPOINT_DIR}/{n}" for n in names if (self.dir / n).exists() or n != MARKER]

    def _state_file(self, seq: int) -> Path:
        return self.dir / f"state-{seq}.npz"

    def write(self, state: TransientState, stepper: dict, rows_of=None) -> None:
        """Collective. ``rows_of()`` returns the number of time-series rows on disk (after flush)."""
        fields = {k: self.layout.gather(getattr(state, k)) for k in ("u", "v", "a")}
        arrays = dict(z=state.z, zd=state.zd, zdd=state.zdd, **fields) if self.comm.rank == 0 else None
        self.write_arrays(state.t, arrays, stepper, rows_of)

    def write_arrays(self, t_s: float, arrays: dict | None, stepper: dict, rows_of=None, meta: dict | None = None
                     ) -> None:
        """Collective: a checkpoint at time ``t_s`` [s] of ``arrays`` (name -> array, rank 0's are
        stored) and the JSON-able ``stepper`` snapshot; ``meta``: more entries for the JSON."""
        if self.flush is not None:
            self.flush()
        rows = int(rows_of()) if rows_of is not None else 0
        rows = self.comm.bcast(rows, root=0)
        seq = self.seq + 1
        if self.comm.rank == 0:
            path = self._state_file(seq)
            atomic_write(path, lambda fh: np.savez(fh, **arrays), sync=True)
            kill_point("checkpoint_state")
            record = {"format": FORMAT, "seq": seq, "t_s": t_s, "mpi_size": self.comm.size, "rows": rows,
                      "voltage_V": self.voltage_V, "stepper": stepper, "case": self.case_digest, **(meta or {})}
            atomic_write(self.dir / POINTER, lambda fh: _write_json(fh, record), sync=True)
            old = self._state_file(self.seq)
            if self.seq and old.exists():
                old.unlink()
        self.comm.barrier()
        self.seq = seq
        self.written += 1


def _write_json(fh, meta: dict) -> None:
    data = json_bytes(meta, indent=1)
    half = len(data) // 2
    fh.write(data[:half])
    fh.flush()
    kill_point("checkpoint_tmp")                 # killed with half a JSON in the temporary file
    fh.write(data[half:])


def mark_started(out_dir: Path, comm, digest: dict) -> None:
    """A fresh run into ``out_dir``: drop any older checkpoint and record the case (collective)."""
    directory = Path(out_dir) / CHECKPOINT_DIR
    if comm.rank == 0:
        directory.mkdir(parents=True, exist_ok=True)
        meta = {"format": FORMAT, "case": digest}
        # the record first: killed in between, the directory still holds a consistent older run
        write_json_atomic(directory / MARKER, meta, sync=True, indent=1)
        for old in [directory / POINTER, *directory.glob("*.npz*")]:     # states, a reduced model
            old.unlink(missing_ok=True)
    comm.barrier()


def _read_json(path: Path) -> tuple[dict | None, str | None]:
    """(content, None) or (None, why it cannot be used)."""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        return None, "is not UTF-8 text"
    except json.JSONDecodeError as exc:
        return None, f"is not valid JSON (truncated or corrupt: {exc.msg} at line {exc.lineno})"
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror})"
    if not isinstance(meta, dict):
        return None, "is not a JSON object"
    return meta, None


class CellLayout:
    """Partition-independent storage of a FE Function's local array: per input cell, the values of
    its DOFs. ``gather`` collects the owned cells on rank 0 (n_cells_global x DOFs per cell);
    ``scatter`` fills a local array (owned + ghost DOFs) from that table."""

    def __init__(self, space):
        msh = space.mesh
        comm = msh.comm
        tdim = msh.topology.dim
        imap = msh.topology.index_map(tdim)
        self.comm = comm
        self.n_owned = imap.size_local
        n_local = imap.size_local + imap.num_ghosts
        self.n_global = imap.size_global
        self.original = np.asarray(msh.topology.original_cell_index, dtype=np.int64)[:n_local]
        dofmap = space.dofmap
        bs = dofmap.bs
        cells = np.asarray(dofmap.list.array, dtype=np.int64).reshape(n_local, -1)
        self.dofs = (cells[:, :, None] * bs + np.arange(bs)).reshape(n_local, -1)
        index_map = dofmap.index_map
        self.local_size = (index_map.size_local + index_map.num_ghosts) * dofmap.index_map_bs

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        own = slice(0, self.n_owned)
        parts = self.comm.gather((self.original[own], values[self.dofs[own]]), root=0)
        if self.comm.rank != 0:
            return None
        table = np.zeros((self.n_global, self.dofs.shape[1]))
        for index, rows in parts:
            table[index] = rows
        return table

    def scatter(self, table: np.ndarray) -> np.ndarray:
        if table.shape != (self.n_global, self.dofs.shape[1]):
            raise ValueError(f"checkpoint field has shape {table.shape}, the mesh needs "
                             f"{(self.n_global, self.dofs.shape[1])}")
        out = np.zeros(self.local_size)
        out[self.dofs] = table[self.original]
        return out


def case_digest(case) -> dict:
    """The parts of the resolved case a resumed run must share with the checkpointed one (all of it
    except the end time, the checkpoint interval and the output options)."""
    from app.case.validate import to_dict

    data = json.loads(json.dumps(jsonable(to_dict(case)), default=str))   # as the records store it
    data.pop("output", None)
    data.pop("source", None)
    transient = data.get("transient", {})
    for key in ("end_time_s", "checkpoint_interval_steps"):
        transient.pop(key, None)
    return data


_MISSING = object()


def _section_types(cls, key: str) -> list:
    """The dataclasses field ``key`` of dataclass ``cls`` holds (``X``, ``X | None``, ``list[X]``, a list of
    a tagged union), else []."""
    if cls is None or not dataclasses.is_dataclass(cls):
        return []
    hint = typing.get_type_hints(cls).get(key)
    if hint is typing.Any:
        # a top-level section owned by another package (lumped, transient): typed Any in Case
        from app.case.schema import _section_types as owned_sections

        hint = owned_sections().get(key)
    if typing.get_origin(hint) is list:
        hint = typing.get_args(hint)[0]
    return [tp for tp in (hint, *typing.get_args(hint)) if dataclasses.is_dataclass(tp)]


def _member(types: list, record):
    """The one of ``types`` a record (dict) is: the only one, or the tagged-union member of its ``kind``."""
    if len(types) == 1:
        return types[0]
    kind = record.get("kind") if isinstance(record, dict) else None
    return next((tp for tp in types if typing.get_args(typing.get_type_hints(tp).get("kind")) == (kind,)), None)


def _field_default(cls, key: str):
    """The schema default of field ``key`` of ``cls`` as the records store it, or _MISSING."""
    if cls is None or not dataclasses.is_dataclass(cls):
        return _MISSING
    for f in dataclasses.fields(cls):
        if f.name == key and f.default is not dataclasses.MISSING:
            return json.loads(json.dumps(jsonable(f.default), default=str))
    return _MISSING


def _differences(a, b, prefix="", cls=None) -> list[str]:
    """Dotted keys where the checkpointed record ``a`` and the resumed case's digest ``b`` differ, walking
    sections and lists of sections with their schema classes (``cls``). A key the record lacks (a later
    version added it) matches when the resumed case leaves it at its schema default, so a program update
    does not strand older checkpoints."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for key in sorted(set(a) | set(b)):
            path = f"{prefix}.{key}" if prefix else key
            if key not in a and b[key] == _field_default(cls, key):
                continue
            types = _section_types(cls, key)
            value_a, value_b = a.get(key), b.get(key)
            if isinstance(value_a, list) and isinstance(value_b, list) and types and len(value_a) == len(value_b):
                for i, (item_a, item_b) in enumerate(zip(value_a, value_b)):
                    out += _differences(item_a, item_b, f"{path}[{i}]", _member(types, item_b))
            else:
                out += _differences(value_a, value_b, path, _member(types, value_b) if types else None)
        return out
    return [] if a == b else [prefix]


def load_checkpoint(out_dir: Path, layout: CellLayout, case, digest: dict) -> Resumed | None:
    """Read the checkpoint of ``out_dir`` on every rank; None when the run was killed before its
    first checkpoint (start again from t = 0); CaseError (exit 2) when there is none, it is
    unreadable, belongs to a different case or mesh, or lies after the case's end time."""
    found = read_checkpoint(out_dir, layout.comm, case, digest)
    if found is None:
        return None
    meta, data = found
    pointer = Path(out_dir) / CHECKPOINT_DIR / POINTER
    try:
        u, v, a = (layout.scatter(data[k]) for k in ("u", "v", "a"))
    except ValueError as exc:
        raise CaseError(str(pointer), "mesh", str(exc)) from None
    state = TransientState(float(meta["t_s"]), u, v, a, data["z"], data["zd"], data["zdd"])
    return Resumed(state, meta["stepper"], float(meta["voltage_V"]), int(meta["rows"]), int(meta["seq"]))


def read_checkpoint(out_dir: Path, comm, case, digest: dict, needs: tuple[str, ...] = ()
                    ) -> tuple[dict, dict] | None:
    """(JSON record, arrays of its state file) of the checkpoint of ``out_dir`` on every rank, or
    None when the run was killed before its first checkpoint; CaseError as ``load_checkpoint``.
    ``needs``: more files of the checkpoint directory the record must name under these keys
    (checked to exist, e.g. the modal tier's reduced model)."""
    file = case.source
    directory = Path(out_dir) / CHECKPOINT_DIR
    pointer = directory / POINTER
    verdict = None
    if comm.rank == 0:
        verdict = _check_pointer(directory, case, needs)
    verdict = comm.bcast(verdict, root=0)
    if "error" in verdict:
        raise CaseError(*verdict["error"])
    meta = verdict["meta"]
    from app.case.schema import Case

    changed = _differences(meta["case"], digest, cls=Case)
    if changed:
        raise CaseError(file, changed[0], "differs from the checkpointed run (only transient.end_time_s, "
                                          "transient.checkpoint_interval_steps and output.* may change on resume)")
    if verdict["started_only"]:
        return None
    if float(meta["t_s"]) > case.transient.end_time_s * (1 + 1e-12):
        raise CaseError(file, "transient.end_time_s", f"{case.transient.end_time_s:g} s is before the checkpoint's "
                                                      f"time {float(meta['t_s']):g} s in {pointer}")
    # written whole before the JSON names it: unreadable only when damaged afterwards (disk, hand)
    data = read_on_root(directory / f"state-{meta['seq']}.npz", comm, load_arrays, "a checkpoint state")
    return meta, data


def load_arrays(path: Path) -> dict:
    """Every array of an npz file, by name (loaded, the file closed)."""
    with np.load(path) as npz:
        return {k: np.array(npz[k]) for k in npz.files}


def read_on_root(path: Path, comm, reader, what: str):
    """Collective: ``reader(path)`` on rank 0, its value on every rank. A KeyError from the reader (an entry
    missing: a file of another version; ``what`` names its content) or an unreadable file is a one-line
    CaseError naming the file, raised on every rank."""
    value, why = None, None
    if comm.rank == 0:
        try:
            value = reader(path)
        except KeyError as exc:
            why = f"has no {exc.args[0]!r} (not {what} of this version)"
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            why = f"cannot be read (truncated or corrupt: {exc})"
    why = comm.bcast(why, root=0)
    if why:
        raise CaseError(str(path), None, why)
    return comm.bcast(value, root=0)


def _check_pointer(directory: Path, case, needs: tuple[str, ...] = ()) -> dict:
    """Rank 0: {"meta", "started_only"} of the checkpoint in ``directory``, or {"error": CaseError
    arguments} (the verdict is broadcast, so every rank raises the same error)."""
    pointer, marker = directory / POINTER, directory / MARKER
    out_dir = str(directory.parent)
    if pointer.exists():
        meta, why = _read_json(pointer)
        if meta is None:
            return {"error": (str(pointer), None, f"checkpoint {why}")}
        if meta.get("format") != FORMAT:
            return {"error": (str(pointer), "format", f"unknown checkpoint format {meta.get('format')!r}")}
        missing = [k for k in ("seq", "t_s", "rows", "voltage_V", "stepper", "case") if k not in meta]
        if missing:
            return {"error": (str(pointer), missing[0], "missing in the checkpoint")}
        state = directory / f"state-{meta['seq']}.npz"
        if not state.is_file():
            return {"error": (str(pointer), "seq", f"the state file {state.name} it names is missing")}
        for key in needs:
            if key not in meta:
                return {"error": (str(pointer), key, "missing in the checkpoint")}
            if not (directory / str(meta[key])).is_file():
                return {"error": (str(pointer), key, f"the file {meta[key]} it names is missing")}
        return {"meta": meta, "started_only": False}
    if marker.exists():
        meta, why = _read_json(marker)
        if meta is None or "case" not in meta:
            return {"error": (str(marker), None, f"run record {why or 'has no case'}")}
        return {"meta": meta, "started_only": True}
    return {"error": (out_dir, "--resume", f"no checkpoint in {out_dir} (expected {pointer})")}
