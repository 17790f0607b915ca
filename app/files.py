"""The one place that writes result files whole: through a temporary file and a rename, so a killed
process leaves the old or the new file, never a mix (JSON: summary.json, sweep.json, checkpoint
records; HDF5 of field frames). Time series grow row by row instead: app/series.py."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np


def atomic_write(path: Path, write: Callable, sync: bool = False) -> None:
    """``write(fh)`` into ``path`` + ".tmp", then rename it to ``path``. ``sync``: fsync before the
    rename (survives power loss; checkpoints)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        write(fh)
        if sync:
            fh.flush()
            os.fsync(fh.fileno())
    os.replace(tmp, path)


def replace_file(path: Path, data: bytes, sync: bool = False) -> None:
    atomic_write(path, lambda fh: fh.write(data), sync)


def jsonable(obj):
    """``obj`` with numpy scalars as Python numbers, non-finite floats as null, complex as {re, im}."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, complex):
        return {"re": obj.real, "im": obj.imag}
    return obj


def json_bytes(data, indent: int = 2) -> bytes:
    return json.dumps(jsonable(data), indent=indent).encode()


def write_json_atomic(path: Path, data, sync: bool = False, indent: int = 2) -> None:
    """The one JSON writer: ``data`` as JSON through a temporary file and a rename."""
    replace_file(Path(path), json_bytes(data, indent), sync)


def write_h5_atomic(path: Path, datasets: dict[str, np.ndarray], attrs: dict[str, dict] | None = None) -> None:
    """An HDF5 file of ``datasets`` (name -> array) written under a temporary name, closed, renamed."""
    import h5py

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with h5py.File(tmp, "w") as f:
        for name, values in datasets.items():
            ds = f.create_dataset(name, data=values)
            for key, value in (attrs or {}).get(name, {}).items():
                ds.attrs[key] = value
    os.replace(tmp, path)
