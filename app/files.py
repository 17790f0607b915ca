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
    """An HDF5 file of ``datasets`` (name -> array; a name with slashes makes its groups) written under a temporary
    name, closed, renamed. ``attrs``: name -> {attribute: value} of a dataset, or of a group (``""`` or ``"/"``: the
    file's root; a group no dataset makes is created). Numeric arrays and their float, int and str attributes go
    through h5py's low-level API (the field output writes hundreds of small datasets per batch: h5py's high-level
    create_dataset and attribute set cost about 4x more), the groups made once each; the file is built in memory
    (h5py's core driver) and written to disk whole at its close, one write instead of one per dataset; it reads
    back as h5py's own (same types, str as UTF-8 strings)."""
    import h5py

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    attrs = attrs or {}
    size = sum(getattr(v, "nbytes", 0) for v in datasets.values())
    # the memory image grows by block_size: about the data's size, so it is not copied again and again
    with h5py.File(tmp, "w", driver="core", backing_store=True, block_size=max(2**16, size // 4)) as f:
        low = _LowLevel(f)
        for name, values in datasets.items():
            ds = low.dataset(name, values)
            if ds is None:
                ds = f.create_dataset(name, data=values).id
            if name in attrs:
                for key, value in attrs[name].items():
                    low.attribute(ds, key, value)
        for name, values in attrs.items():
            if name not in datasets:
                group = low.group(name.strip("/"))
                for key, value in values.items():
                    low.attribute(group, key, value)
    os.replace(tmp, path)


class _LowLevel:
    """Datasets, groups and attributes of file ``f`` through h5py's low-level API, the property list, types,
    dataspaces and groups made once per file (a batch of field frames writes hundreds of datasets of a few shapes
    into a few groups)."""

    def __init__(self, f):
        import h5py
        from h5py import h5d, h5p, h5s, h5t

        self.f = f
        self.h5d, self.h5s = h5d, h5s        # looked up once: an import statement per dataset costs as much as a call
        self.lcpl = h5p.create(h5p.LINK_CREATE)
        self.lcpl.set_char_encoding(h5t.CSET_UTF8)
        self.types: dict = {}
        self.spaces: dict = {}
        self.groups: dict = {"": f.id}
        self.str_dtype = h5py.string_dtype()
        self.str_type = h5t.py_create(self.str_dtype, logical=True)
        self.scalar = h5s.create(h5s.SCALAR)

    def group(self, name: str):
        """The group ``name`` (slashes: nested; "" the root), created with its parents unless it exists."""
        gid = self.groups.get(name)
        if gid is None:
            from h5py import h5g

            parent, _, base = name.rpartition("/")
            pid = self.group(parent)
            try:
                gid = h5g.open(pid, base.encode())
            except KeyError:
                gid = h5g.create(pid, base.encode(), lcpl=self.lcpl)
            self.groups[name] = gid
        return gid

    def _type(self, dtype):
        tid = self.types.get(dtype)
        if tid is None:
            from h5py import h5t

            tid = self.types[dtype] = h5t.py_create(dtype)
        return tid

    def dataset(self, name: str, values):
        """The low-level dataset of a numeric array (None for anything else: h5py's high level writes it)."""
        arr = values if isinstance(values, np.ndarray) else np.asarray(values)
        if arr.dtype.kind not in "fiub" or arr.ndim == 0 or arr.size == 0:
            return None
        if not arr.flags.c_contiguous:              # a frame's values are contiguous: no copy, no call
            arr = np.ascontiguousarray(arr)
        space = self.spaces.get(arr.shape)
        if space is None:
            space = self.spaces[arr.shape] = self.h5s.create_simple(arr.shape)
        tid = self._type(arr.dtype)
        parent, _, base = name.strip("/").rpartition("/")
        ds = self.h5d.create(self.group(parent), base.encode(), tid, space, lcpl=self.lcpl)
        ds.write(self.h5s.ALL, self.h5s.ALL, arr, mtype=tid)       # the memory type is the file's: no lookup
        return ds

    def attribute(self, ds, key: str, value) -> None:
        """A float, int or str attribute of a dataset or group (its low-level id) through the low-level API,
        anything else through h5py's AttributeManager."""
        import h5py
        from h5py import h5a

        if isinstance(value, str):
            data, tid, mtype = np.array(value, dtype=self.str_dtype), self.str_type, None
        elif isinstance(value, (float, int, np.floating, np.integer)) and not isinstance(value, bool):
            data = np.array(value)
            tid = mtype = self._type(data.dtype)
        else:
            (h5py.Group(ds) if isinstance(ds, h5py.h5g.GroupID) else h5py.Dataset(ds)).attrs[key] = value
            return
        h5a.create(ds, key.encode(), tid, self.scalar).write(data, mtype=mtype)
