"""XDMF time series of the FE fields of a transient run (ParaView), at a chosen output interval.

dolfinx 0.5 samples higher-degree fields at the vertices when writing XDMF, so displacement and
potential are interpolated to P1 first (the same as :class:`app.exports.ModeShapeExport`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from dolfinx import fem, io

from app.compat import scalar_space, vector_space


class FieldSeriesExport:
    """``write(t)`` appends the current displacement [m] and electric potential [V] of ``model``
    (from ``solution()``, a full u-phi PETSc vector) when t has reached the next multiple of
    ``interval_s``. The file is opened for each output and closed after it, so a killed run leaves
    a readable series. ``resume_from_s``: continue an existing series (steps after that time,
    written by a killed run, are removed from the XDMF first); if it cannot be opened (killed while
    writing), the resumed run starts ``<stem>.part<k>.xdmf`` next to it."""

    def __init__(self, path: Path, model, solution, interval_s: float, resume_from_s: float | None = None):
        self.path = Path(path)
        self.model = model
        self.solution = solution
        self.interval_s = float(interval_s)
        mesh = model.mesh
        self.comm = mesh.comm
        self.u_p1 = fem.Function(vector_space(mesh, "Lagrange", 1), name="displacement")
        self.phi_p1 = fem.Function(scalar_space(mesh, "Lagrange", 1), name="potential")
        self._phi_space, self._phi_map = model.W.sub(1).collapse()
        self._phi = fem.Function(self._phi_space)
        self.written = 0
        self.next_s = 0.0
        if resume_from_s is not None:
            self.next_s = self._next_after(resume_from_s)
            if self._can_append(resume_from_s):
                return
            k = 2
            while Path(f"{self.path.with_suffix('')}.part{k}.xdmf").exists():
                k += 1
            self.path = Path(f"{self.path.with_suffix('')}.part{k}.xdmf")
        with io.XDMFFile(self.comm, str(self.path), "w") as file:
            file.write_mesh(mesh)

    def _can_append(self, t_s: float) -> bool:
        ok = False
        if self.comm.rank == 0 and self.path.exists():
            try:
                _drop_steps_after(self.path, t_s)
                import h5py

                with h5py.File(self.path.with_suffix(".h5"), "r") as f:
                    ok = "Mesh" in f
            except (OSError, ET.ParseError):
                ok = False
        return self.comm.bcast(ok, root=0)

    def _next_after(self, t: float) -> float:
        return (math.floor(t / self.interval_s * (1 + 1e-9) + 1e-9) + 1) * self.interval_s

    def write(self, t: float) -> None:
        if t < self.next_s - 1e-9 * self.interval_s:
            return
        x = self.solution()
        self.u_p1.interpolate(self.model.displacement(x))
        n_owned = self._phi_space.dofmap.index_map.size_local * self._phi_space.dofmap.index_map_bs
        self._phi.x.array[:n_owned] = x.array_r[np.asarray(self._phi_map[:n_owned])]
        self._phi.x.scatter_forward()
        self.phi_p1.interpolate(self._phi)
        with io.XDMFFile(self.comm, str(self.path), "a") as file:
            file.write_function(self.u_p1, float(t))
            file.write_function(self.phi_p1, float(t))
        self.written += 1
        self.next_s = self._next_after(t)

    def close(self) -> None:
        """Nothing stays open between outputs."""


def _drop_steps_after(path: Path, t_s: float) -> None:
    """Remove the time steps later than ``t_s`` from every temporal collection of an XDMF file
    (their data stays in the .h5, unreferenced)."""
    tree = ET.parse(path)
    for collection in tree.iter("Grid"):
        if collection.get("CollectionType") != "Temporal":
            continue
        for grid in list(collection.findall("Grid")):
            time = grid.find("Time")
            if time is not None and float(time.get("Value")) > t_s * (1 + 1e-12):
                collection.remove(grid)
    tmp = path.with_name(path.name + ".tmp")
    tree.write(tmp, xml_declaration=True, encoding="utf-8")
    tmp.replace(path)
