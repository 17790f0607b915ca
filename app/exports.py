"""Exports: objects with ``write(...)``; solvers never open files."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
from dolfinx import fem, io

from app.compat import vector_space


class ModeShapeExport:
    """Mode shapes of one electrical state as an XDMF series (ParaView: 'time' = mode number).

    dolfinx 0.5 samples higher-degree fields at vertices, so shapes are interpolated to P1 first."""

    def __init__(self, path: Path, mesh):
        self.path = path
        self.file = io.XDMFFile(mesh.comm, str(path), "w")
        self.file.write_mesh(mesh)
        self.p1 = fem.Function(vector_space(mesh, "Lagrange", 1), name="displacement")

    def write(self, displacement: fem.Function, index: float) -> None:
        self.p1.interpolate(displacement)
        self.file.write_function(self.p1, float(index))

    def close(self):
        self.file.close()


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, complex):
        return {"re": obj.real, "im": obj.imag}
    return obj


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON via a temporary file and rename, so a killed run never leaves half a file."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_jsonable(data), indent=2))
    os.replace(tmp, path)
