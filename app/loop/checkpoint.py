"""Checkpoints of a transient run, and resuming from them: one module for every tier.

A checkpoint holds everything needed to continue a run bit-identically: the engine's state arrays (the FE
fields per input cell, or the reduced coordinates, the lumped state ...) and its JSON-able record (step
controller, counters, drive), the loop's own state (the steady-state watch) and the number of time-series
rows on disk. Whatever else the next steps depend on is a function of these, recomputed on resume.

Layout in ``DIR/checkpoint/``: ``state-<seq>.npz`` (the arrays) and ``checkpoint.json`` (the record), both
written by rank 0 through a temporary file, fsync and a rename, the JSON last. The JSON names the ``seq``
of a complete state file, so a run killed at any moment leaves either the previous or the new checkpoint,
never a mix; the older state file is removed after the JSON points past it. An engine may add files of
its own once per run (the modal tier's reduced model); the record names them under ``files``.

A fresh run first writes ``run.json`` (the case digest) and removes any older checkpoint, so a run killed
before its first checkpoint (e.g. during the harmonic start) is known: ``--resume`` then starts it again
from t = 0 instead of refusing.

Format 2 (this one) records ``tier``, ``engine`` (the engine's record) and ``loop``; format 1, written by
piezodyn before the one run loop, is read for the FE tier (its record maps one to one) and refused with one
line for the other tiers, whose state arrays changed.
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

CHECKPOINT_DIR = "checkpoint"
POINTER = "checkpoint.json"
MARKER = "run.json"
FORMAT = 2


@dataclass
class Found:
    """A checkpoint to resume from: its record (``t_s``, ``rows``, ``seq``, ``tier``, ``engine``, ``loop``,
    ``files``) and its state arrays (every rank holds them)."""

    record: dict
    arrays: dict
    pointer: Path           # the checkpoint's JSON (for messages)

    @property
    def t_s(self) -> float:
        return float(self.record["t_s"])

    @property
    def rows(self) -> int:
        return int(self.record["rows"])

    @property
    def seq(self) -> int:
        return int(self.record["seq"])

    @property
    def engine(self) -> dict:
        return self.record["engine"]

    @property
    def loop(self) -> dict:
        return self.record.get("loop") or {}

    def file(self, out_dir: Path, key: str) -> Path:
        """An engine file of the checkpoint (``files`` names it)."""
        return Path(out_dir) / CHECKPOINT_DIR / str(self.record["files"][key])


class CheckpointWriter:
    """Collective ``write(t_s, arrays, engine_record, loop_record, rows)``; ``due(steps)`` every
    ``interval_steps`` accepted steps. ``files``: engine files of the checkpoint directory (key -> name)."""

    def __init__(self, out_dir: Path, comm, interval_steps: int, tier: str, case_digest: dict, seq: int = 0,
                 files: dict | None = None):
        self.dir = Path(out_dir) / CHECKPOINT_DIR
        self.comm = comm
        self.interval_steps = int(interval_steps)
        self.tier = tier
        self.case_digest = case_digest
        self.seq = seq
        self.files_ = dict(files or {})
        self.written = 0
        if comm.rank == 0:
            self.dir.mkdir(parents=True, exist_ok=True)
        comm.barrier()

    def due(self, steps: int) -> bool:
        return self.interval_steps > 0 and steps % self.interval_steps == 0

    def steps_to_next(self, steps: int) -> int:
        """Accepted steps until the next checkpoint is due (a large number when only the end writes one)."""
        if self.interval_steps <= 0:
            return 2**62
        return self.interval_steps - steps % self.interval_steps

    def files(self) -> list[str]:
        """The checkpoint's files, relative to the output directory."""
        names = [MARKER, POINTER] + ([self._state_file(self.seq).name] if self.seq else []) + list(self.files_.values())
        return [f"{CHECKPOINT_DIR}/{n}" for n in names if (self.dir / n).exists() or n != MARKER]

    def _state_file(self, seq: int) -> Path:
        return self.dir / f"state-{seq}.npz"

    def write(self, t_s: float, arrays: dict | None, engine: dict, loop: dict, rows: int) -> None:
        """Collective: a checkpoint at time ``t_s`` [s] of ``arrays`` (rank 0's are stored), the engine's and
        the loop's JSON-able records, and ``rows`` time-series rows on disk (flushed before)."""
        rows = self.comm.bcast(int(rows), root=0)
        seq = self.seq + 1
        if self.comm.rank == 0:
            path = self._state_file(seq)
            atomic_write(path, lambda fh: np.savez(fh, **arrays), sync=True)
            kill_point("checkpoint_state")
            record = {"format": FORMAT, "seq": seq, "t_s": t_s, "mpi_size": self.comm.size, "rows": rows,
                      "tier": self.tier, "engine": engine, "loop": loop, "files": self.files_,
                      "case": self.case_digest}
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
        for old in [directory / POINTER, *directory.glob("*.npz*")]:     # states, engine files
            old.unlink(missing_ok=True)
    comm.barrier()


def write_engine_file(out_dir: Path, comm, name: str, writer) -> str:
    """Rank 0 writes an engine file of the checkpoint directory once per run (``writer(fh)``, atomically);
    returns its name for :class:`CheckpointWriter`'s ``files``."""
    if comm.rank == 0:
        directory = Path(out_dir) / CHECKPOINT_DIR
        directory.mkdir(parents=True, exist_ok=True)
        atomic_write(directory / name, writer, sync=True)
    comm.barrier()
    return name


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


def case_digest(case) -> dict:
    """The parts of the resolved case a resumed run must share with the checkpointed one (all of it
    except the end time, the checkpoint interval and the output options)."""
    from app.case.validate import to_dict

    data = json.loads(json.dumps(jsonable(to_dict(case)), default=str))   # as the records store it
    data.pop("output", None)
    data.pop("source", None)
    transient = data.get("transient") or {}
    for key in ("end_time_s", "checkpoint_interval_steps"):
        transient.pop(key, None)
    lumped = data.get("lumped") or {}
    lumped.pop("duration_s", None)
    return data


_MISSING = object()


def _section_types(cls, key: str) -> list:
    """The dataclasses field ``key`` of dataclass ``cls`` holds (``X``, ``X | None``, ``list[X]``, a list of
    a tagged union), else []."""
    if cls is None or not dataclasses.is_dataclass(cls):
        return []
    hint = typing.get_type_hints(cls).get(key)
    if hint is typing.Any:
        # a top-level section with a module of its own (lumped, transient): typed Any in Case
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
        if f.name != key:
            continue
        if f.default is not dataclasses.MISSING:
            return json.loads(json.dumps(jsonable(f.default), default=str))
        if f.default_factory is not dataclasses.MISSING:
            from app.case.validate import to_dict

            value = f.default_factory()
            value = to_dict(value) if dataclasses.is_dataclass(value) else value
            return json.loads(json.dumps(jsonable(value), default=str))
    return _MISSING


def _removed_from(cls, key: str) -> bool:
    """Whether ``key`` is not a field of the schema class ``cls`` (any more)."""
    return dataclasses.is_dataclass(cls) and key not in {f.name for f in dataclasses.fields(cls)}


def _differences(a, b, prefix="", cls=None) -> list[str]:
    """Dotted keys where the checkpointed record ``a`` and the resumed case's digest ``b`` differ, walking
    sections and lists of sections with their schema classes (``cls``). A key the record lacks (a later
    version added it) matches when the resumed case leaves it at its schema default, and a key the schema
    no longer has (a later version removed it, e.g. reduction.ring_points of the old modal motor) is not
    compared: nothing reads it now, so a program update does not strand older checkpoints."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for key in sorted(set(a) | set(b)):
            path = f"{prefix}.{key}" if prefix else key
            if key not in a and b[key] == _field_default(cls, key):
                continue
            if key not in b and _removed_from(cls, key):
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


def read_checkpoint(out_dir: Path, comm, case, digest: dict, tier: str) -> Found | None:
    """The checkpoint of ``out_dir`` on every rank, or None when the run was killed before its first
    checkpoint (start again from t = 0). CaseError (exit 2, one line, the same on every rank) when there is
    none, it is unreadable, belongs to a different case (named by its first differing key, before anything
    about the tier's files) or tier, lies after the case's end time, or names an engine file that is
    missing."""
    file = case.source
    directory = Path(out_dir) / CHECKPOINT_DIR
    pointer = directory / POINTER
    verdict = _check_pointer(directory, tier) if comm.rank == 0 else None
    verdict = comm.bcast(verdict, root=0)
    if "error" in verdict:
        raise CaseError(*verdict["error"])
    meta = verdict["meta"]
    from app.case.schema import Case

    changed = _differences(meta["case"], digest, cls=Case)
    if changed:
        before = meta["case"]
        if before.get("title") != digest.get("title") or before.get("scene") != digest.get("scene"):
            # another case altogether (a title or scene of its own): say so, not only its first differing key
            raise CaseError(file, changed[0], f"differs from the checkpointed run, which is a run of another case "
                                              f"({before.get('title')!r}, {len(changed)} keys differ): resume with "
                                              "that case, or run this one into another directory")
        raise CaseError(file, changed[0], "differs from the checkpointed run (only transient.end_time_s, "
                                          "transient.checkpoint_interval_steps and output.* may change on resume)")
    if verdict["started_only"]:
        return None
    if "refused" in verdict:
        raise CaseError(*verdict["refused"])
    end = case.transient.end_time_s if case.transient is not None else case.lumped.duration_s
    key = "transient.end_time_s" if case.transient is not None else "lumped.duration_s"
    if float(meta["t_s"]) > end * (1 + 1e-12):
        raise CaseError(file, key, f"{end:g} s is before the checkpoint's time {float(meta['t_s']):g} s in {pointer}")
    # written whole before the JSON names it: unreadable only when damaged afterwards (disk, hand)
    arrays = read_on_root(directory / f"state-{meta['seq']}.npz", comm, load_arrays, "a checkpoint state")
    return Found(meta, arrays, pointer)


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


def _format_1(meta: dict, pointer: Path) -> tuple[dict | None, tuple | None]:
    """A format-1 record (piezodyn before the one run loop) as format 2, or the one-line refusal: the FE tier's
    maps one to one; the modal tier's state arrays and the motor's changed."""
    stepper = meta.get("stepper")
    if "reduced_model" in meta or not isinstance(stepper, dict) or "controller" not in stepper:
        return None, (str(pointer), "format", "a checkpoint of an earlier version of the modal tier (before the one "
                                              "run loop): its state cannot be continued; run the case again")
    stepper = dict(stepper)
    steady = stepper.pop("steady_state", None)
    out = dict(meta)
    out.update({"format": FORMAT, "tier": "fe", "engine": {"voltage_V": meta["voltage_V"], "stepper": stepper},
                "loop": {"steady_state": steady}, "files": {}})
    return out, None


def _check_pointer(directory: Path, tier: str) -> dict:
    """Rank 0: {"meta", "started_only"} of the checkpoint in ``directory``, or {"error": CaseError arguments}
    (the verdict is broadcast, so every rank raises the same error). A record of another tier or format that
    cannot be continued is returned as "refused", raised after the case comparison (which names what the user
    changed, e.g. the tier)."""
    pointer, marker = directory / POINTER, directory / MARKER
    out_dir = str(directory.parent)
    if pointer.exists():
        meta, why = _read_json(pointer)
        if meta is None:
            return {"error": (str(pointer), None, f"checkpoint {why}")}
        if "case" not in meta or not isinstance(meta["case"], dict):
            return {"error": (str(pointer), "case", "missing in the checkpoint")}
        refused = None
        if meta.get("format") == 1:
            missing = [k for k in ("seq", "t_s", "rows", "voltage_V", "stepper") if k not in meta]
            if missing:
                return {"error": (str(pointer), missing[0], "missing in the checkpoint")}
            meta, refused = _format_1(meta, pointer)
            if meta is None:
                return {"meta": {"case": _read_json(pointer)[0]["case"]}, "started_only": False, "refused": refused}
        elif meta.get("format") != FORMAT:
            return {"error": (str(pointer), "format", f"unknown checkpoint format {meta.get('format')!r}")}
        missing = [k for k in ("seq", "t_s", "rows", "tier", "engine", "files") if k not in meta]
        if missing:
            return {"error": (str(pointer), missing[0], "missing in the checkpoint")}
        if meta["tier"] != tier:
            refused = (str(pointer), "tier", f"the checkpoint is a run of tier {meta['tier']!r}, this case runs "
                                             f"tier {tier!r}")
        state = directory / f"state-{meta['seq']}.npz"
        if refused is None and not state.is_file():
            return {"error": (str(pointer), "seq", f"the state file {state.name} it names is missing")}
        for key, name in (meta.get("files") or {}).items():
            if refused is None and not (directory / str(name)).is_file():
                return {"error": (str(pointer), f"files.{key}", f"the file {name} it names is missing")}
        verdict = {"meta": meta, "started_only": False}
        if refused is not None:
            verdict["refused"] = refused
        return verdict
    if marker.exists():
        meta, why = _read_json(marker)
        if meta is None or "case" not in meta:
            return {"error": (str(marker), None, f"run record {why or 'has no case'}")}
        return {"meta": meta, "started_only": True}
    return {"error": (out_dir, "--resume", f"no checkpoint in {out_dir} (expected {pointer})")}


def warm_start_directory(case) -> Path:
    """``transient.start_from`` as a path (relative to the case file)."""
    path = Path(case.transient.start_from)
    if not path.is_absolute() and case.source:
        path = Path(case.source).parent / path
    return path


def read_warm_start(case, comm, tier: str) -> Found:
    """The last checkpoint of the result directory ``transient.start_from`` names, on every rank: the state a warm
    start begins from. One-line CaseError naming ``transient.start_from`` (the same on every rank) when the
    directory holds no complete checkpoint, or one of another tier; the engine checks that the state fits its
    model (:meth:`app.reduced.engine.ModalEngine.start`)."""
    key = "transient.start_from"
    directory = warm_start_directory(case)
    verdict = None
    if comm.rank == 0:
        if not directory.is_dir():
            verdict = {"error": (case.source, key, f"{directory} is not a directory (a result directory of an earlier "
                                                   "run is needed)")}
        elif not (directory / CHECKPOINT_DIR / POINTER).is_file():
            verdict = {"error": (case.source, key, f"{directory} holds no checkpoint (expected "
                                                   f"{directory / CHECKPOINT_DIR / POINTER}; a run that ended "
                                                   "writes one)")}
        else:
            verdict = _check_pointer(directory / CHECKPOINT_DIR, tier)
            if "error" in verdict:
                file, where, why = verdict["error"]
                verdict["error"] = (case.source, key, f"{file}{': ' + where if where else ''}: {why}")
            elif "refused" in verdict:
                file, where, why = verdict["refused"]
                verdict = {"error": (case.source, key, f"{file}: {why}")}
    verdict = comm.bcast(verdict, root=0)
    if "error" in verdict:
        raise CaseError(*verdict["error"])
    meta = verdict["meta"]
    arrays = read_on_root(directory / CHECKPOINT_DIR / f"state-{meta['seq']}.npz", comm, load_arrays,
                          "a checkpoint state")
    return Found(meta, arrays, directory / CHECKPOINT_DIR / POINTER)
