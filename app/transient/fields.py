"""XDMF time series of the FE fields and rigid bodies of a transient run (ParaView), at a chosen
output interval.

Layout: ``<stem>.xdmf`` (the XML, ours) and ``<stem>/mesh.h5`` (vertices, cells, region tags)
plus one ``<stem>/step_<k>.h5`` per output (displacement [m], potential [V] at the vertices; see
:class:`app.exports.VertexFields`). Each output time is a spatial collection of the FE grid
(``fe_body``: displacement, potential, region) and one single-vertex grid per rigid body at its
start position with its displacement, so one Warp By Vector moves the transducer, ball, stem and
rock together.

Why a file per output: a process killed while writing HDF5 can leave that file unreadable; here
it can only hit a step file that the XML does not name yet (step files are written under a
temporary name and renamed), and the XML is replaced atomically after the step file exists. So
after a kill at any moment the XML and every file it names are complete. A resumed run drops the
steps after the checkpoint's time (XML entries and their files) and continues the series.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from app.exports import (
    FE_GRID,
    mesh_grid,
    point_grid,
    step_bytes,
    write_mesh_h5,
    xdmf_document,
)
from app.files import replace_file, write_h5_atomic
from app.killpoint import kill_point


class FieldSeriesExport:
    """``write(t, body_positions)`` appends the current displacement [m] and electric potential [V]
    (``vertex.sample(solution())``: :class:`app.exports.VertexFields` of the FE model and a full u-phi PETSc
    vector, or the modal tier's vertex basis and its coordinates) and the rigid bodies' positions
    (``body_positions``: the rigid state vector z [m]) when t has reached the next multiple of
    ``interval_s``. ``bodies``: (name, slice of z, start position [m]) per rigid body.
    ``resume_from_s``: continue the existing series after that time (later steps are dropped).
    ``scalars``: a callable returning further vertex fields of the current state, {name: (values at the
    vertices on rank 0 (None elsewhere), units)}, e.g. ``contact_pressure_Pa`` (collective)."""

    def __init__(self, path: Path, vertex, solution, interval_s: float, bodies=(), resume_from_s: float | None = None,
                 scalars=None):
        self.path = Path(path)
        self.dir = self.path.with_suffix("")
        self.solution = solution
        self.interval_s = float(interval_s)
        self.bodies = [(name, sl, np.asarray(start, dtype=float)) for name, sl, start in bodies]
        self.vertex = vertex
        self.scalars = scalars
        self.comm = vertex.comm
        self.rank0 = self.comm.rank == 0
        self.steps: list[bytes] = []         # each output's XML, serialised once
        self.next_s = 0.0
        if resume_from_s is not None:
            self.next_s = self._next_after(resume_from_s)
        if self.rank0:
            self.dir.mkdir(parents=True, exist_ok=True)
            if resume_from_s is not None:
                self.steps = [step_bytes(step) for step in _steps_until(self.path, resume_from_s)]
            for stale in self.dir.glob("step_*.h5*"):       # steps of a killed run past the checkpoint
                if _step_index(stale) >= len(self.steps):
                    stale.unlink()
            write_mesh_h5(self.dir / "mesh.h5", self.vertex)
            replace_file(self.path, self._document())
        self.written = self.comm.bcast(len(self.steps), root=0)

    def _next_after(self, t: float) -> float:
        return (math.floor(t / self.interval_s * (1 + 1e-9) + 1e-9) + 1) * self.interval_s

    def files(self) -> list[str]:
        """Names of the files of the series, relative to the output directory."""
        return [self.path.name, f"{self.dir.name}/mesh.h5"] + [f"{self.dir.name}/step_{k:06d}.h5"
                                                               for k in range(self.written)]

    def _document(self) -> bytes:
        return xdmf_document(self.steps, self.path.stem)

    def write(self, t: float, body_positions=None) -> None:
        if t < self.next_s - 1e-9 * self.interval_s:
            return
        sampled = self.vertex.sample(self.solution())
        scalars = self.scalars() if self.scalars is not None else {}
        if self.rank0:
            u, phi = sampled
            k = len(self.steps)
            name = f"step_{k:06d}.h5"
            data = {"displacement": u, "potential": phi, **{key: v for key, (v, _) in scalars.items()}}
            attrs = {"displacement": {"units": "m", "time_s": t}, "potential": {"units": "V", "time_s": t},
                     **{key: {"units": units, "time_s": t} for key, (_, units) in scalars.items()}}
            write_h5_atomic(self.dir / name, data, attrs)
            kill_point("fields_data")                   # the step file exists, the XML does not name it yet
            step = ET.Element("Grid", Name=f"t = {t:.9g} s", GridType="Collection", CollectionType="Spatial")
            ET.SubElement(step, "Time", Value=repr(float(t)))
            step.append(mesh_grid(FE_GRID, self.vertex, f"{self.dir.name}/mesh.h5", f"{self.dir.name}/{name}:",
                                  scalars=list(scalars)))
            z = np.asarray(body_positions, dtype=float) if body_positions is not None else None
            for body, sl, start in self.bodies:
                position = z[sl] if z is not None else start
                step.append(point_grid(body, start, position - start))
            self.steps.append(step_bytes(step))
            replace_file(self.path, self._document())
        self.written += 1
        self.next_s = self._next_after(t)
        kill_point("fields_written")

    def close(self) -> None:
        """Nothing stays open between outputs."""


def _step_index(path: Path) -> int:
    try:
        return int(path.name.split("_", 1)[1].split(".", 1)[0])
    except (IndexError, ValueError):
        return -1


def _steps_until(path: Path, t_s: float) -> list[ET.Element]:
    """The output steps of an existing series at times <= ``t_s`` (none if there is no readable
    series: it is then started again)."""
    try:
        tree = ET.parse(path)
    except (OSError, ET.ParseError):
        return []
    series = tree.find("Domain/Grid")
    if series is None:
        return []
    kept = []
    for step in series.findall("Grid"):
        time = step.find("Time")
        if time is None or float(time.get("Value")) > t_s * (1 + 1e-12):
            break
        kept.append(step)
    return kept
