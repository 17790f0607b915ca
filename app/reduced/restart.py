"""Checkpoints and ``--resume`` of the modal tier: the FE tier's checkpoint files
(:mod:`app.loop.checkpoint`: ``run.json``, ``checkpoint.json``, ``state-<seq>.npz``, written
through temporary files and renames, the JSON last) plus the reduced model, written once.

Why the reduced model is part of the checkpoint (``checkpoint/reduced-model.npz``, written once when
a fresh run has reduced its model): a resumed run must continue with the very matrices, loads, drive
amplitudes and basis vectors the interrupted one used. Recomputing them is not enough: the
eigensolver's round-off, and on another MPI partition the sign of each mode (and the rotation
within a pair of equal frequencies), are not reproducible, and the saved modal coordinates only mean
something in their own basis. So the resumed run loads K_r, M_r, C_r, the load vector, the point
rows, the drive and the basis T (stored per mesh cell in the input cell order, like the FE tier's
fields, so any number of ranks can read it) and skips the reduction.

The compiled loop is deterministic given its inputs and its state arrays (q, v, a, the rigid
bodies' z, zd, zdd, the integer counters and the float controller state: time and step cap; what
else it keeps is recomputed from them at every call, see app/reduced/kernel.py). A checkpoint
stores exactly those arrays (binary, npz) and the number of time-series rows on disk, so a resumed
run repeats the interrupted run's steps bit for bit, on any number of ranks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dolfinx import fem
from petsc4py import PETSc

from app.errors import CaseError
from app.files import atomic_write
from app.loop.checkpoint import CHECKPOINT_DIR, CellLayout, load_arrays, read_on_root

MODEL_FILE = "reduced-model.npz"
MODEL_KEY = "reduced_model"
STATE_ARRAYS = ("q", "v", "a", "z", "zd", "zdd", "istate", "fstate")


@dataclass
class SavedModel:
    """The reduced model of a checkpointed run (replicated on every rank). ``columns``: T as PETSc
    vectors on the current partition (owned entries, full u-phi numbering)."""

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray
    fq: np.ndarray
    sample_rows: np.ndarray
    electrodes: list[str]
    mode_frequencies_Hz: np.ndarray
    charge_rows: dict[str, np.ndarray]
    columns: list[PETSc.Vec]
    drive_scale_V: float
    amplitudes_V: np.ndarray
    phases_rad: np.ndarray


def _owned_size(W) -> int:
    return W.dofmap.index_map.size_local * W.dofmap.index_map_bs


def save_model(out_dir: Path, scene, layout: CellLayout, scale_V: float, amplitudes_V: np.ndarray,
               phases_rad: np.ndarray) -> None:
    """Collective: write the scene's reduced model and drive to ``checkpoint/reduced-model.npz``."""
    basis = scene.basis
    W = scene.model.W
    work = fem.Function(W)
    n_owned = _owned_size(W)
    tables = []
    for column in basis.columns:
        work.x.array[:n_owned] = column.array_r
        work.x.scatter_forward()
        tables.append(layout.gather(work.x.array))
    if layout.comm.rank == 0:
        arrays = {"K": basis.K, "M": basis.M, "C": basis.C, "fq": scene.fq, "sample_rows": scene.sample_rows,
                  "electrodes": np.array(basis.electrodes, dtype=str),
                  "mode_frequencies_Hz": basis.mode_frequencies_Hz,
                  "charge_rows": np.array([basis.charge_rows[n] for n in basis.electrodes]).reshape(
                      len(basis.electrodes), basis.size),
                  "columns": np.stack(tables), "drive_scale_V": np.array(float(scale_V)),
                  "amplitudes_V": np.asarray(amplitudes_V, float), "phases_rad": np.asarray(phases_rad, float)}
        directory = Path(out_dir) / CHECKPOINT_DIR
        atomic_write(directory / MODEL_FILE, lambda fh: np.savez(fh, **arrays), sync=True)
    layout.comm.barrier()


def load_model(out_dir: Path, model, layout: CellLayout) -> SavedModel:
    """Collective: the reduced model of the checkpoint in ``out_dir`` with T on ``model``'s partition."""
    comm = layout.comm
    path = Path(out_dir) / CHECKPOINT_DIR / MODEL_FILE

    def reader(p):
        arrays = load_arrays(p)
        missing = [k for k in SavedModel.__dataclass_fields__ if k not in arrays]
        if missing:
            raise KeyError(missing[0])
        return arrays

    data = read_on_root(path, comm, reader, "a reduced model")
    W = model.W
    n_owned = _owned_size(W)
    columns = []
    for table in data["columns"]:
        try:
            local = layout.scatter(table)
        except ValueError as exc:
            raise CaseError(str(path), "mesh", str(exc)) from None
        vec = PETSc.Vec().createMPI((n_owned, PETSc.DECIDE), comm=comm)
        vec.array_w[:] = local[:n_owned]
        columns.append(vec)
    electrodes = [str(n) for n in data["electrodes"]]
    return SavedModel(data["K"], data["M"], data["C"], data["fq"], data["sample_rows"], electrodes,
                      data["mode_frequencies_Hz"], {n: data["charge_rows"][i] for i, n in enumerate(electrodes)},
                      columns, float(data["drive_scale_V"]), data["amplitudes_V"], data["phases_rad"])


def checkpoint_files(out_dir: Path) -> list[str]:
    """The modal tier's extra checkpoint file, relative to the output directory, if written."""
    path = Path(out_dir) / CHECKPOINT_DIR / MODEL_FILE
    return [f"{CHECKPOINT_DIR}/{MODEL_FILE}"] if path.is_file() else []


