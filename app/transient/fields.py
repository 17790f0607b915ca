"""XDMF time series of the FE fields and rigid bodies of a transient run (ParaView), at frame times
phase-locked to the drive (:func:`frame_schedule`: bursts of frames spread over a drive period, so an
animation shows the vibration, not one phase of it).

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

DEFAULT_PHASES = 8


class FrameSchedule:
    """The times of the field frames, phase-locked to the drive: bursts of ``phases`` frames evenly spaced over
    one drive period (``period_s``), a burst starting every ``interval_periods`` periods from t = 0, or at each of
    ``burst_times_s``. ``next_after(t)``: the first frame time after t (a frame at t itself counts as written);
    ``spacing_s``: the smallest distance between frames (the loop's time tolerance scale)."""

    def __init__(self, period_s: float, phases: int, interval_periods: float | None = None,
                 burst_times_s=None):
        self.period_s = float(period_s)
        self.phases = int(phases)
        self.step_s = self.period_s / self.phases
        offsets = np.arange(self.phases) * self.step_s
        if burst_times_s is not None:
            self.interval_s = None
            self.frames = np.unique(np.add.outer(np.asarray(burst_times_s, dtype=float), offsets).ravel())
            gaps = np.diff(self.frames)
            self.spacing_s = float(min(self.step_s, gaps.min())) if gaps.size else self.step_s
        else:
            self.interval_s = float(interval_periods) * self.period_s
            self.frames = offsets
            self.spacing_s = min(self.step_s, self.interval_s)

    def next_after(self, t: float) -> float:
        after = t + 1e-9 * self.spacing_s
        if self.interval_s is None:
            i = int(np.searchsorted(self.frames, after, side="right"))
            return float(self.frames[i]) if i < self.frames.size else math.inf
        k = math.floor(after / self.interval_s)       # bursts k and k + 1 hold the next frame (they do not overlap)
        frames = np.concatenate([k * self.interval_s + self.frames, (k + 1) * self.interval_s + self.frames])
        return float(frames[frames > after].min())


def frame_schedule(case) -> FrameSchedule:
    """The field frames of a transient case: ``output.field_phases`` per period (default 8) of
    ``transient.drive.frequency_Hz``, bursts every ``output.field_interval_periods`` or at
    ``output.field_burst_times_s``; by default every ``field_phases x output_interval_s`` rounded to whole
    periods (at least one), so a run writes about as many frames as one per output_interval_s, at every phase."""
    output, cfg = case.output, case.transient
    period = 1.0 / cfg.drive.frequency_Hz
    phases = output.field_phases or DEFAULT_PHASES
    if output.field_burst_times_s is not None:
        return FrameSchedule(period, phases, burst_times_s=output.field_burst_times_s)
    interval = output.field_interval_periods
    if interval is None:
        interval = max(1, round(phases * cfg.output_interval_s / period))
    return FrameSchedule(period, phases, interval_periods=interval)


class FieldSeriesExport:
    """``write(t, body_positions)`` appends the current displacement [m] and electric potential [V]
    (``vertex.sample(solution())``: :class:`app.exports.VertexFields` of the FE model and a full u-phi PETSc
    vector, or the modal tier's vertex basis and its coordinates) and the rigid bodies' positions
    (``body_positions``: the rigid state vector z [m]) when t has reached the next frame time of ``schedule``
    (:class:`FrameSchedule`). ``bodies``: (name, slice of z, start position [m]) per rigid body.
    ``resume_from_s``: continue the existing series after that time (later steps are dropped)."""

    def __init__(self, path: Path, vertex, solution, schedule: FrameSchedule, bodies=(),
                 resume_from_s: float | None = None):
        self.path = Path(path)
        self.dir = self.path.with_suffix("")
        self.solution = solution
        self.schedule = schedule
        self.interval_s = schedule.spacing_s          # the loop's tolerance scale
        self.bodies = [(name, sl, np.asarray(start, dtype=float)) for name, sl, start in bodies]
        self.vertex = vertex
        self.comm = vertex.comm
        self.rank0 = self.comm.rank == 0
        self.steps: list[bytes] = []         # each output's XML, serialised once
        self.next_s = self._first()
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

    def _first(self) -> float:
        return float(self.schedule.frames[0])          # t = 0 for regular bursts, else the first burst

    def _next_after(self, t: float) -> float:
        return self.schedule.next_after(t)

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
        if self.rank0:
            u, phi = sampled
            k = len(self.steps)
            name = f"step_{k:06d}.h5"
            write_h5_atomic(self.dir / name, {"displacement": u, "potential": phi},
                            {"displacement": {"units": "m", "time_s": t}, "potential": {"units": "V", "time_s": t}})
            kill_point("fields_data")                   # the step file exists, the XML does not name it yet
            step = ET.Element("Grid", Name=f"t = {t:.9g} s", GridType="Collection", CollectionType="Spatial")
            ET.SubElement(step, "Time", Value=repr(float(t)))
            step.append(mesh_grid(FE_GRID, self.vertex, f"{self.dir.name}/mesh.h5", f"{self.dir.name}/{name}:"))
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
