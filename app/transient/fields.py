"""XDMF time series of the FE fields and rigid bodies of a transient run (ParaView, meshio), at frame times
phase-locked to the drive (:func:`frame_schedule`: bursts of frames spread over a drive period, so an
animation shows the vibration, not one phase of it).

Layout: ``<stem>.xdmf`` (the XML, ours) and ``<stem>/mesh.h5`` (vertices, cells, region tags) plus
``<stem>/frames_<k>.h5``, one HDF5 file per batch of frames named by its first frame k, with frame k's
displacement [m] and potential [V] at the vertices (see :class:`app.exports.VertexFields`) as the datasets
``displacement/step_<k>`` and ``potential/step_<k>`` (one group per field, its units the group's attribute
``units``; the batch's times in ``time_s``, their frame indices in ``step``, the frames' peaks in the root attribute
``region_peaks_json``: a few HDF5 objects per frame, not a group and attributes each, since their number was
what writing a batch cost). Each output time is one uniform grid of the FE mesh (``fe_body``:
displacement, potential, region) in a temporal collection, the layout meshio's TimeSeriesReader and
ParaView's XDMF readers both read. The rigid bodies, drawn with their shapes
(:mod:`app.transient.body_shapes`), are the companion file ``transient_bodies.xdmf`` written at the same
times: one triangle grid of all bodies (``rigid_bodies``: cell values ``body``, the index into the
``names`` attribute of ``<stem>/bodies.h5``, and ``sector``, stripes that show a spin) at their start,
with each vertex's displacement [m] in the frame's dataset ``bodies/displacement/step_<k>``. Both files are
written in the reference configuration with their displacement, so one Warp By Vector (scale 1) on each puts
the transducer and the bodies where they are; meshio reads the points once and the displacement per time.
The modal tier's contact sites with ``output.contact_pressure`` are a second companion,
``transient_contact_sites.xdmf`` (:class:`ContactSiteCloud`: a point cloud with the sites' displacement and
``contact_pressure_Pa``, their area and contact index in ``<stem>/contact_sites.h5``).

Why batches, and why a file per batch: writing each frame at once cost the modal tier more than its steps
(one HDF5 file per frame, the whole XML rewritten per frame, one product of the bases per frame). So frames
are buffered (at most ``FRAMES_PER_FILE``) and written together by ``flush()``: one HDF5 file, one rewrite of
the XML, and in the modal tier one product of each basis with all the batch's coordinates
(app/reduced/engine.py ReducedVertexFields's ``expand``). A process killed while writing HDF5 can leave that
file unreadable; here it can only hit a batch file that the XML does not name yet (it is written under a
temporary name and renamed), and the XML is replaced atomically after the batch file exists. So after a
kill at any moment the XML and every file it names are complete.

The modal tier's compiled loop takes the frames itself (``engine_frames``: app/reduced/kernel.py Frames, given
:meth:`FrameSchedule.upcoming`), at the steps the loop would, so the loop does not stop it at every frame time; and
its batches are expanded and written by a writer thread on rank 0 while the compiled loop, which releases the GIL,
steps on (``writer_thread``): the run waits for the field output only at its end. A batch the thread has not
finished rides in a checkpoint as the buffered frames do.

Checkpoints (app/loop/loop.py): a frame at or before a checkpoint's time is either on disk when the checkpoint is
written or in the checkpoint itself. The FE tier's buffered frames (sampled fields, large) are written before every
checkpoint; the modal tier's (a time, its coordinates q and body coordinates z: a few hundred numbers) ride in the
checkpoint (:meth:`FieldSeriesExport.checkpoint_record`: the times in its record, q and z in its state arrays), so
its batches are not cut at checkpoints (with a contact site cloud, ``output.contact_pressure``, whose site states
are larger, they are written before it as the FE tier's). A resumed run (``resume_from_s``, then
:meth:`FieldSeriesExport.resume` with the checkpoint's record) keeps the frames that were on disk at the checkpoint
(XML entries and the batch files they name), removes every other frame file (a batch written after the checkpoint,
or not yet named), buffers the checkpoint's frames again and continues the series. Its batches are the run in one
go's (cut at the same frames), so its values are that run's bit for bit; resumed with another checkpoint interval,
the FE tier's cut differs and the values agree to round-off.
"""

from __future__ import annotations

import json
import math
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.drive import is_driven
from app.exports import (
    FE_GRID,
    data_item,
    extra_fields,
    mesh_grid,
    step_bytes,
    write_mesh_h5,
    xdmf_document,
)
from app.files import replace_file, write_h5_atomic
from app.killpoint import kill_point

BODY_GRID = "rigid_bodies"      # name of the bodies' grid in the companion file
SITE_GRID = "contact_sites"     # name of the contact sites' grid in their companion file
CONTACT_PRESSURE = "contact_pressure_Pa"     # the contact pressure's name in every tier's files [Pa]
FRAME_PEAKS = "region_peaks_json"       # attribute of a frame's displacement: that frame's peaks per region
DEFAULT_PHASES = 8
#: at most this many frames are buffered before they are written (one HDF5 file, one rewrite of the XML); the run
#: loop also flushes before every checkpoint and at the end
FRAMES_PER_FILE = 64
#: and at most about this much memory for a batch's vertex values (a large mesh writes smaller batches): an FE frame
#: buffers its sampled fields, a modal batch expands all its frames at once; estimated as 64 doubles per vertex and
#: frame (displacement, potential, the derived fields and the region-wise averaged values they come from)
BATCH_BYTES = 256 * 2**20


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

    @property
    def ordered(self) -> bool:
        """Whether :meth:`next_after` is the first of :meth:`upcoming` after its argument: true unless bursts
        overlap (an interval shorter than the burst)."""
        return self.interval_s is None or self.interval_s >= self.period_s

    def upcoming(self, from_s: float, count: int) -> np.ndarray:
        """The first ``count`` frame times at or after the frame time ``from_s``, in order, each the very float
        :meth:`next_after` returns (the same arithmetic), so a step loop that takes a frame at the first step at or
        after one of them and then skips to the first after t + 1e-9 spacing takes the frames ``next_after``
        gives (the modal kernel's field frames, app/reduced/kernel.py Frames)."""
        if self.interval_s is None:
            i = int(np.searchsorted(self.frames, from_s, side="left"))
            return self.frames[i:i + count].copy()
        first = math.floor(from_s / self.interval_s) - 1         # one burst early: from_s / interval rounds
        bursts = -(-count // self.phases) + 2
        times = np.concatenate([k * self.interval_s + self.frames for k in range(max(first, 0), first + bursts + 1)])
        return times[times >= from_s][:count]


def frame_schedule(case) -> FrameSchedule:
    """The field frames of a transient case: ``output.field_phases`` per period (default 8) of
    ``transient.drive.frequency_Hz``, bursts every ``output.field_interval_periods`` or at
    ``output.field_burst_times_s``; by default every ``field_phases x output_interval_s`` rounded to whole
    periods (at least one), so a run writes about as many frames as one per output_interval_s, at every phase.
    A case with no drive (app.drive.is_driven) and none of these keys: a frame every output_interval_s."""
    output, cfg = case.output, case.transient
    locked = any(getattr(output, k) is not None for k in ("field_phases", "field_interval_periods",
                                                          "field_burst_times_s"))
    if not locked and not is_driven(case):
        # nothing oscillates at the drive frequency (a quasi-static press, a free fall): no phase to lock to, a
        # frame at t = 0 and at every multiple of output_interval_s
        return FrameSchedule(cfg.output_interval_s, 1, interval_periods=1)
    period = 1.0 / cfg.drive.frequency_Hz
    phases = output.field_phases or DEFAULT_PHASES
    if output.field_burst_times_s is not None:
        return FrameSchedule(period, phases, burst_times_s=output.field_burst_times_s)
    interval = output.field_interval_periods
    if interval is None:
        interval = max(1, round(phases * cfg.output_interval_s / period))
    return FrameSchedule(period, phases, interval_periods=interval)


@dataclass
class ContactSiteCloud:
    """The contact sites of a run (the modal tier's: where its contact law is evaluated), written as a point cloud
    companion of the field series, ``<stem minus _fields>_contact_sites.xdmf``: one Polyvertex grid of the sites at
    their reference position ``points`` (n, 3) [m], with per frame their displacement [m] (Warp By Vector at scale
    1 moves them with the structure) and the normal contact pressure ``contact_pressure_Pa`` [Pa] (the FE tier's
    name), and once their area ``site_area_m2`` [m^2] (the share of the contact surface each one stands for: the
    sum of pressure x area over a contact's sites is its normal force) and ``contact`` (index into ``names``).
    ``state()`` returns (displacement (n, 3), pressure (n,)) of the current state on rank 0 (None elsewhere)."""

    points: np.ndarray
    area_m2: np.ndarray
    contact: np.ndarray
    names: list
    state: Callable


@dataclass
class _Frame:
    """A frame written by ``write`` and not yet flushed. Rank 0 holds the data: the modal tier's coordinates
    ``state`` (expanded at the flush), or the sampled ``fields`` (name -> (values, units or None)) of the FE
    tier, the further vertex ``scalars`` (name -> (values, units)), the bodies' and the sites' state."""

    t: float
    state: np.ndarray | None = None
    fields: dict | None = None
    scalars: dict | None = None
    peaks: dict | None = None
    z: np.ndarray | None = None
    bodies: np.ndarray | None = None
    sites: tuple | None = None


class _StepTemplate:
    """A frame's serialised XML element with three placeholders, the time value, the frame's batch file
    (``<folder>/<file>``) and its dataset name in each field's group (``step_<k>``); ``fill(t, data_file, step)``
    returns the frame's bytes."""

    TIME = "@time@"
    FILE = "@file@"
    STEP = "@step@"

    def __init__(self, text: bytes):
        if text.count(self.TIME.encode()) != 1:
            raise ValueError("a frame template holds one time value")
        self.text = text

    def fill(self, t: str, data_file: str, step: str) -> bytes:
        return (self.text.replace(self.TIME.encode(), t.encode()).replace(self.FILE.encode(), data_file.encode())
                .replace(self.STEP.encode(), step.encode()))


def _time_text(t: float | str) -> str:
    return t if isinstance(t, str) else repr(float(t))


class FieldSeriesExport:
    """``write(t, body_positions)`` takes a frame of the current displacement [m] and electric potential [V]
    (``vertex.sample(solution())``: :class:`app.exports.VertexFields` of the FE model and a full u-phi PETSc
    vector; or, with a ``vertex`` that has ``expand`` (the modal tier's vertex basis), its coordinates, kept
    until the batch is written and expanded then, all of the batch at once) and the rigid bodies' displacement
    (``body_positions``: the packed body coordinates z [m, rad]) when t has reached the next frame time of
    ``schedule`` (:class:`FrameSchedule`). Frames are written in batches of at most ``batch_frames`` (and about
    BATCH_BYTES of vertex values), by ``flush()`` (collective: the run loop calls it before every checkpoint
    unless ``carries``) and by ``close()``; ``checkpoint_record()`` and ``resume(record)`` carry the buffer
    through a checkpoint (module docstring). ``bodies``: None, or a function of the scene size [m] (the FE
    mesh's largest extent) returning the :class:`app.transient.body_shapes.BodyMeshes` of the run (called on
    rank 0). ``resume_from_s``: continue the existing series after that time (later steps are dropped).
    ``scalars``: a callable returning further vertex fields of the current state, {name: (values at the vertices
    on rank 0 (None elsewhere), units)}, e.g. ``contact_pressure_Pa`` (collective). ``sites``: None, or the
    :class:`ContactSiteCloud` written as the companion ``<stem minus _fields>_contact_sites.xdmf``.
    ``writer_thread``: a series whose buffer rides in the checkpoint (``carries``) writes its batches on a thread
    of rank 0 while the engine steps on (:meth:`_submit`); False: at the flush, as the others."""

    def __init__(self, path: Path, vertex, solution, schedule: FrameSchedule, bodies=None,
                 resume_from_s: float | None = None, scalars=None, sites: ContactSiteCloud | None = None,
                 batch_frames: int = FRAMES_PER_FILE, writer_thread: bool = True):
        self.path = Path(path)
        self.dir = self.path.with_suffix("")
        self.bodies_path = self.path.with_name(self.path.stem.replace("_fields", "") + "_bodies.xdmf")
        self.sites_path = self.path.with_name(self.path.stem.replace("_fields", "") + "_contact_sites.xdmf")
        self.sites = sites if sites is not None and len(sites.points) else None
        self.site_steps: list[bytes] = []
        self.solution = solution
        self.schedule = schedule
        self.interval_s = schedule.spacing_s          # the loop's tolerance scale
        self.vertex = vertex
        self.expands = hasattr(vertex, "expand")      # the modal tier: coordinates now, vertex values per batch
        self.scalars = scalars
        self.batch_frames = max(1, int(batch_frames))
        self.pending: list[_Frame] = []
        self.comm = vertex.comm
        self.rank0 = self.comm.rank == 0
        self.bodies = None
        self.steps: list[bytes] = []         # each output's XML, serialised once
        self.body_steps: list[bytes] = []
        self.data_files: list[str] = []      # the frame files the XML names, in order (every rank)
        self._templates: dict[tuple, _StepTemplate] = {}
        self._kept: list[ET.Element] = []
        self.next_s = self._first()
        if resume_from_s is not None:
            self.next_s = self._next_after(resume_from_s)
        kept_peaks: dict = {}
        if self.rank0:
            if bodies is not None:
                x = vertex.mesh_arrays["geometry"]
                meshes = bodies(float(np.ptp(x, axis=0).max()) if len(x) else 1.0)
                self.bodies = meshes if meshes.names else None
            self.dir.mkdir(parents=True, exist_ok=True)
            kept = []
            if resume_from_s is not None:
                kept = _steps_until(self.path, resume_from_s)
                body_steps = _steps_until(self.bodies_path, resume_from_s) if self.bodies is not None else []
                site_steps = _steps_until(self.sites_path, resume_from_s) if self.sites is not None else []
                # a kill between the XMLs (companions first): keep the frames every file has
                n = min([len(kept), *([len(body_steps)] if self.bodies is not None else []),
                         *([len(site_steps)] if self.sites is not None else [])])
                kept = kept[:n]
                self.steps = [step_bytes(step) for step in kept]
                self.body_steps = [step_bytes(step) for step in body_steps[:n]]
                self.site_steps = [step_bytes(step) for step in site_steps[:n]]
                kept_peaks = _kept_peaks(self.path.parent, kept)
            self._kept = kept
            self._drop_stale(kept)
            write_mesh_h5(self.dir / "mesh.h5", self.vertex)
            if self.bodies is not None:
                write_bodies_h5(self.dir / "bodies.h5", self.bodies)
            if self.sites is not None:
                c = self.sites
                n = len(c.points)
                write_h5_atomic(self.dir / "contact_sites.h5",
                                {"points": np.asarray(c.points, dtype=float),
                                 "vertices": np.arange(n, dtype=np.int64).reshape(n, 1),
                                 "site_area_m2": np.asarray(c.area_m2, dtype=float),
                                 "contact": np.asarray(c.contact, dtype=np.int32)},
                                {"points": {"units": "m"},
                                 "site_area_m2": {"units": "m^2", "meaning": "the contact surface a site stands for: "
                                                  "pressure x area summed over a contact's sites is its normal force"},
                                 "contact": {"meaning": "index of the site's contact in names",
                                             "names": list(c.names)}})
            self._replace_documents()
        self.written = self.comm.bcast(len(self.steps), root=0)
        self.data_files = self.comm.bcast(self.data_files, root=0)
        frame_bytes = self.comm.bcast(8 * 64 * int(getattr(vertex, "n_nodes", 0)) if self.rank0 else None, root=0)
        self.batch_frames = max(1, min(self.batch_frames, BATCH_BYTES // max(frame_bytes, 1)))
        # the modal tier's buffered frames are a few coordinates each: they ride in the checkpoint
        # (checkpoint_record, resume) instead of being written before it, so batches are not cut there
        self.carries = self.expands and not self.comm.bcast(self.sites is not None, root=0)
        self.has_bodies = self.comm.bcast(self.bodies is not None, root=0)
        self.has_sites = self.comm.bcast(self.sites is not None, root=0)
        # peaks per region over the frames of the series (app.fe.derived.region_peaks), every rank; a resumed run
        # starts from the kept frames' own peaks (each frame keeps its own), so a kill changes nothing
        self.peaks: dict | None = None
        if getattr(vertex, "derived", ()):
            self.peaks = self.comm.bcast(kept_peaks if self.rank0 else None, root=0)
        # frames an engine takes at its own steps (the modal kernel: app/reduced/kernel.py Frames), a function
        # returning [(t, q, z)] taken since its last call; the loop then does not stop the engine at frame times
        self.engine_frames: Callable | None = None
        # the writer thread of a carrying series (rank 0, made at its first batch: _submit), its batches not yet
        # known to be written [(future, frames)], the peaks of those written, and its CPU and busy wall time [s]
        self.writer_thread = writer_thread
        self._writer = None
        self._jobs: list[tuple] = []
        self._written_peaks: list = []
        self.writer_cpu_s = 0.0
        self.writer_wall_s = 0.0
        self.due_s = 1e-9 * self.interval_s                # a frame is due at the first step at or after next_s - due_s
        self.after_s = 1e-9 * self.schedule.spacing_s      # a frame at t: the next is after t + after_s (next_after)

    @property
    def engine_can_take(self) -> bool:
        """Whether an engine may take this series' frames itself (:attr:`engine_frames`): frames of coordinates
        only (no vertex ``scalars``, no contact site cloud, whose states the engine does not hold) in a schedule
        whose next frame is the first after a time (:meth:`FrameSchedule.ordered`)."""
        return self.expands and self.scalars is None and not self.has_sites and self.schedule.ordered

    def _first(self) -> float:
        return float(self.schedule.frames[0])          # t = 0 for regular bursts, else the first burst

    def _next_after(self, t: float) -> float:
        return self.schedule.next_after(t)

    def _drop_stale(self, kept: list[ET.Element]) -> None:
        """Keep the frame files the steps ``kept`` name; remove the others (a killed run's past the checkpoint)."""
        self.data_files = _data_files(kept, self.dir.name)
        for stale in [*self.dir.glob("frames_*.h5*"), *self.dir.glob("step_*.h5*")]:
            if stale.name not in self.data_files:
                stale.unlink()

    def checkpoint_record(self) -> tuple[dict, dict]:
        """The series' part of a checkpoint: (record, arrays). The record (JSON-able; rank 0's is stored): the
        number of frames on disk and, when the buffer rides in the checkpoint (``carries``: the modal tier), the
        buffered frames' times; the arrays (rank 0's, stored with the engine's state, bit for bit): their
        coordinates q (``fields_buffered_q``: frames x coordinates) and body coordinates z
        (``fields_buffered_z``). Without ``carries`` the run loop flushes before the checkpoint."""
        times, arrays, buffered = [], {}, self.pending
        if self.carries and self.rank0:
            # the batches the writer thread has not finished ride along: a kill before it names them in the XML
            # loses nothing (a batch it finishes after the checkpoint is cut on resume and written again, the same)
            self._reap()
            buffered = [frame for _, frames in self._jobs for frame in frames] + self.pending
            if buffered:
                times = [f.t for f in buffered]
                arrays["fields_buffered_q"] = np.array([f.state for f in buffered])
                if buffered[0].z is not None:
                    arrays["fields_buffered_z"] = np.array([f.z for f in buffered])
        return {"on_disk": self.written - len(buffered), "buffered_s": times}, arrays

    def resume(self, record: dict | None, arrays: dict | None = None) -> None:
        """Continue from a checkpoint's :meth:`checkpoint_record` (collective; ``arrays``: the checkpoint's state
        arrays, rank 0's read): the series cut to the frames that were on disk then (a batch written after the
        checkpoint can hold frames at or before its time: they are in its record) and its buffered frames
        buffered again, so the batches are the run in one go's. A checkpoint without a record (an older
        version's) had every frame at or before its time on disk; one whose record lists the buffered frames'
        coordinates (``buffered``, an older version's) is read as well."""
        if not record:
            return
        on_disk = int(record["on_disk"])
        if self.rank0 and on_disk < len(self.steps):
            self._kept = self._kept[:on_disk]
            self.steps, self.body_steps = self.steps[:on_disk], self.body_steps[:on_disk]
            self.site_steps = self.site_steps[:on_disk]
            self._drop_stale(self._kept)
            self._replace_documents()
            if self.peaks is not None:
                self.peaks = _kept_peaks(self.path.parent, self._kept)
        self.data_files = self.comm.bcast(self.data_files, root=0)
        if self.peaks is not None:
            self.peaks = self.comm.bcast(self.peaks, root=0)
        self.written = self.comm.bcast(len(self.steps), root=0)
        buffered = [(frame["t_s"], frame["q"], frame.get("z")) for frame in record.get("buffered") or []]
        if record.get("buffered_s"):
            q = arrays.get("fields_buffered_q") if self.rank0 and arrays else None
            z = arrays.get("fields_buffered_z") if self.rank0 and arrays else None
            buffered = [(t, None if q is None else q[k], None if z is None else z[k])
                        for k, t in enumerate(record["buffered_s"])]
        for t, q, z in buffered:
            self.pending.append(_Frame(float(t), state=None if q is None else np.asarray(q, dtype=float),
                                       z=None if z is None else np.asarray(z, dtype=float), scalars={}))
            self.written += 1
        # batches that were full but not yet written at the checkpoint: written again, cut where the run cut them
        while len(self.pending) >= self.batch_frames:
            self._flush_batch()

    def files(self) -> list[str]:
        """Names of the files of the series, relative to the output directory (after ``close()``)."""
        bodies = [self.bodies_path.name, f"{self.dir.name}/bodies.h5"] if self.has_bodies else []
        sites = [self.sites_path.name, f"{self.dir.name}/contact_sites.h5"] if self.has_sites else []
        return [self.path.name, f"{self.dir.name}/mesh.h5", *bodies, *sites] + [f"{self.dir.name}/{name}"
                                                                        for name in self.data_files]

    def _document(self) -> bytes:
        return xdmf_document(self.steps, self.path.stem, getattr(self.vertex, "region_names", None))

    def _replace_documents(self) -> None:
        """The companions' XML first: a kill between them leaves the FE series no longer than theirs."""
        if self.bodies is not None:
            replace_file(self.bodies_path, xdmf_document(self.body_steps, self.bodies_path.stem))
        if self.sites is not None:
            replace_file(self.sites_path, xdmf_document(self.site_steps, self.sites_path.stem))
        replace_file(self.path, self._document())

    def write(self, t: float, body_positions=None) -> None:
        """Buffer the frames an engine took (:attr:`engine_frames`), then a frame at ``t`` if one is due."""
        if self.engine_frames is not None:
            taken = self.engine_frames()
            for frame_t, q, z in taken:
                self._add(_Frame(float(frame_t), state=q if self.rank0 else None, scalars={},
                                 z=z if self.rank0 and self.bodies is not None else None), last=False)
            if taken:
                self.next_s = self._next_after(float(taken[-1][0]))
        if t < self.next_s - 1e-9 * self.interval_s:
            return
        x = self.solution()
        frame = _Frame(float(t))
        if self.expands:
            if self.rank0:
                frame.state = np.array(x, dtype=float, copy=True)
        else:
            sampled = self.vertex.sample(x)
            derived, frame.peaks = self._derived(x)
            if self.rank0:
                u, phi = sampled
                frame.fields = {"displacement": (u, "m"), "potential": (phi, "V"),
                                **{key: (v, None) for key, v in derived.items()}}
        scalars = self.scalars() if self.scalars is not None else {}
        site_state = self.sites.state() if self.sites is not None else None
        if self.rank0:
            frame.scalars = scalars
            if self.bodies is not None and body_positions is not None:
                frame.z = np.array(body_positions, dtype=float, copy=True)     # displaced at the flush
            frame.sites = site_state
        self._add(frame)

    def _add(self, frame: _Frame, last: bool = True) -> None:
        """Buffer a frame (a batch full: write it) and, when it is the ``last`` of those taken, move to the next
        frame time."""
        self.pending.append(frame)
        self.written += 1
        if last:
            self.next_s = self._next_after(frame.t)
        kill_point("fields_written")
        if len(self.pending) >= self.batch_frames:
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames, in batches of at most ``batch_frames``: each one HDF5 file (under a temporary
        name, renamed), then the XMLs naming them. Collective (the modal tier's peaks are computed on rank 0 and
        broadcast). A series whose buffer rides in the checkpoint (``carries``: the modal tier) hands its batches to
        a writer thread on rank 0 (:meth:`_submit`) and goes on; :meth:`close` waits for them."""
        while self.pending:
            self._flush_batch()

    def _flush_batch(self) -> None:
        frames, self.pending = self.pending[:self.batch_frames], self.pending[self.batch_frames:]
        first = self.written - len(self.pending) - len(frames)
        name = f"frames_{first:06d}.h5"
        self.data_files.append(name)
        if self.carries and self.writer_thread:
            if self.rank0:
                self._submit(first, name, frames)
            return
        peaks = self._write_batch(first, name, frames) if self.rank0 else None
        if self.expands:
            self._merge(self.comm.bcast(peaks, root=0))

    def _merge(self, peaks: list) -> None:
        """Merge frames' peaks into the series' (the largest of each region's values)."""
        from app.fe.derived import merge_peaks

        if self.peaks is None:
            return
        for frame in peaks or ():
            if frame is not None:
                merge_peaks(self.peaks, frame)

    def _submit(self, first: int, name: str, frames: list[_Frame]) -> None:
        """Hand a batch to the writer thread (rank 0): it expands, writes and names the batches in order while the
        engine steps on (the modal kernel releases the GIL: app/reduced/kernel.py run). Until it is written, the
        batch's frames stay in :attr:`_jobs` and ride in a checkpoint (:meth:`checkpoint_record`)."""
        from concurrent.futures import ThreadPoolExecutor

        self._reap()
        if self._writer is None:
            self._writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="field-writer")
        self._jobs.append((self._writer.submit(self._timed_batch, first, name, frames), frames))

    def _timed_batch(self, first: int, name: str, frames: list[_Frame]) -> list:
        cpu, wall = time.thread_time(), time.perf_counter()
        try:
            return self._write_batch(first, name, frames)
        finally:
            self.writer_cpu_s += time.thread_time() - cpu
            self.writer_wall_s += time.perf_counter() - wall

    def _reap(self) -> None:
        """Take the written batches off :attr:`_jobs` (their peaks kept for :meth:`_collect`); a batch that failed
        raises here, at the next batch or checkpoint (rank 0)."""
        while self._jobs and self._jobs[0][0].done():
            job, _ = self._jobs.pop(0)
            self._written_peaks.extend(job.result() or ())

    def _collect(self) -> None:
        """Wait for the writer thread's batches and merge their peaks on every rank (collective)."""
        peaks = None
        if self.rank0:
            for job, _ in self._jobs:
                job.result()
            self._reap()
            peaks, self._written_peaks = self._written_peaks, []
        if self.carries and self.expands:
            self._merge(self.comm.bcast(peaks, root=0))

    def _write_batch(self, first: int, name: str, frames: list[_Frame]) -> list | None:
        """Write a batch (rank 0): the modal tier's frames expanded (one product of each basis with all their
        coordinates), the bodies displaced, one HDF5 file, then the XMLs. The frames are not changed (a batch in
        the writer thread rides in a checkpoint meanwhile). Returns the frames' peaks when they are computed here
        (the modal tier's), else None."""
        fields = [frame.fields for frame in frames]
        peaks = [frame.peaks for frame in frames]
        if self.expands:
            expanded = self.vertex.expand(np.column_stack([f.state for f in frames]))
            peaks = [e[3] for e in expanded]
            fields = [{"displacement": (u, "m"), "potential": (phi, "V"),
                       **{key: (v, None) for key, v in derived.items()}} for u, phi, derived, _ in expanded]
        datasets, attrs = batch_index(first, [frame.t for frame in frames])
        frame_peaks = {}
        # the bodies of all the batch's frames displaced at once: frame index -> displacement
        moved = [k for k, frame in enumerate(frames) if frame.z is not None] if self.bodies is not None else []
        moved = dict(zip(moved, self.bodies.displacements(np.array([frames[k].z for k in moved])))) if moved else {}
        for k, (frame, values_of, peaks_k) in enumerate(zip(frames, fields, peaks), start=first):
            step = f"step_{k:06d}"
            for key, (values, units) in {**values_of, **frame.scalars}.items():
                datasets[f"{key}/{step}"] = values
                if units is not None:
                    attrs[key] = {"units": units}
            if peaks_k is not None:
                frame_peaks[step] = peaks_k
            bodies = moved.get(k - first, frame.bodies)
            if bodies is not None:
                datasets[f"bodies/displacement/{step}"] = bodies
                attrs["bodies/displacement"] = {"units": "m"}
            if frame.sites is not None:
                (datasets[f"contact_sites/displacement/{step}"],
                 datasets[f"contact_sites/{CONTACT_PRESSURE}/{step}"]) = frame.sites
                attrs["contact_sites/displacement"] = {"units": "m"}
                attrs[f"contact_sites/{CONTACT_PRESSURE}"] = {"units": "Pa"}
        if frame_peaks:
            attrs["/"] = {FRAME_PEAKS: json.dumps(frame_peaks)}
        write_h5_atomic(self.dir / name, datasets, attrs)
        kill_point("fields_data")                   # the batch file exists, the XML does not name it yet
        data_file = f"{self.dir.name}/{name}"
        for k, (frame, values_of) in enumerate(zip(frames, fields), start=first):
            step, t = f"step_{k:06d}", repr(float(frame.t))
            extra = extra_fields({**{key: v for key, (v, _) in values_of.items()
                                     if key not in ("displacement", "potential")},
                                  **{key: v for key, (v, _) in frame.scalars.items()}})
            self.steps.append(self._template("fe", tuple(extra)).fill(t, data_file, step))
            if self.bodies is not None:
                self.body_steps.append(self._template("bodies").fill(t, data_file, step))
            if self.sites is not None:
                self.site_steps.append(self._template("sites").fill(t, data_file, step))
        self._replace_documents()
        return peaks if self.expands else None

    def _template(self, grid: str, extra: tuple = ()) -> _StepTemplate:
        """A frame's XML element of ``grid`` ("fe" with the vertex fields ``extra``, "bodies", "sites") as bytes
        with the time and the frame's data path left to fill: built and serialised once per series, not once per
        frame (the elements of a series differ only there)."""
        key = (grid, extra)
        if key not in self._templates:
            t, data_file, name = _StepTemplate.TIME, _StepTemplate.FILE, _StepTemplate.STEP
            if grid == "fe":
                step = mesh_grid(FE_GRID, self.vertex, f"{self.dir.name}/mesh.h5", f"{data_file}:", list(extra),
                                 frame=f"/{name}")
                step.insert(0, ET.Element("Time", Value=t))
            elif grid == "bodies":
                step = body_grid(self.bodies, t, self.dir.name, data_file, name)
            else:
                step = self._site_grid(t, data_file, name)
            self._templates[key] = _StepTemplate(step_bytes(step))
        return self._templates[key]

    def _site_grid(self, t: float | str, data_file: str, step: str) -> ET.Element:
        """One output of the contact sites: the points at their reference position, one vertex cell each, the
        displacement and pressure of frame ``step`` in ``data_file`` (``<folder>/<file>``: its datasets
        ``contact_sites/displacement/<step>``, ``contact_sites/contact_pressure_Pa/<step>``), the static area and
        contact index."""
        n, where = len(self.sites.points), f"{self.dir.name}/contact_sites.h5"
        grid = ET.Element("Grid", Name=SITE_GRID, GridType="Uniform")
        ET.SubElement(grid, "Time", Value=_time_text(t))
        topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n), NodesPerElement="1")
        data_item(topo, f"{where}:/vertices", (n, 1), "Int")
        geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        data_item(geo, f"{where}:/points", (n, 3))
        for attr_name, kind, source, shape, number in (
                ("displacement", "Vector", f"{data_file}:/contact_sites/displacement/{step}", (n, 3), "Float"),
                (CONTACT_PRESSURE, "Scalar", f"{data_file}:/contact_sites/{CONTACT_PRESSURE}/{step}", (n,), "Float"),
                ("site_area_m2", "Scalar", f"{where}:/site_area_m2", (n,), "Float"),
                ("contact", "Scalar", f"{where}:/contact", (n,), "Int")):
            attr = ET.SubElement(grid, "Attribute", Name=attr_name, AttributeType=kind, Center="Node")
            data_item(attr, source, shape, number, 8 if number == "Float" else 4)
        return grid

    def _derived(self, x) -> tuple[dict, dict | None]:
        """The output's derived vertex fields (rank 0; name -> array) and this frame's peaks per region (every
        rank), merged into the running peaks. Collective."""
        if self.peaks is None:
            return {}, None
        from app.fe.derived import merge_peaks

        fields, peaks = self.vertex.derived_frame(x)
        peaks = self.comm.bcast(peaks, root=0)
        merge_peaks(self.peaks, peaks)
        return fields or {}, peaks

    def close(self) -> None:
        """Write the buffered frames and wait for the writer thread (collective); nothing stays open between
        outputs."""
        try:
            self.flush()
        finally:
            self._collect()
            if self._writer is not None:
                self._writer.shutdown()
                self._writer = None


def write_bodies_h5(path: Path, bodies) -> None:
    """The bodies' triangles at their start (``points`` [m], ``triangles``, cell values ``body`` and ``sector``)."""
    b = bodies
    write_h5_atomic(path, {"points": b.points, "triangles": b.triangles, "body": b.body, "sector": b.sector},
                    {"points": {"units": "m"},
                     "body": {"meaning": "index of the cell's rigid body in names", "names": b.names},
                     "sector": {"meaning": "alternating stripes round a body of revolution (its spin)"}})


def body_grid(bodies, t: float | str, folder: str, data_file: str, step: str) -> ET.Element:
    """One output of the bodies: their triangles at the start (``<folder>/bodies.h5``) and the displacement of
    frame ``step`` in ``data_file`` (``<folder>/<file>``, its dataset ``bodies/displacement/<step>``)."""
    b, where = bodies, f"{folder}/bodies.h5"
    grid = ET.Element("Grid", Name=BODY_GRID, GridType="Uniform")
    ET.SubElement(grid, "Time", Value=_time_text(t))
    topo = ET.SubElement(grid, "Topology", TopologyType="Triangle", NumberOfElements=str(len(b.triangles)),
                         NodesPerElement="3")
    data_item(topo, f"{where}:/triangles", b.triangles.shape, "Int")
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    data_item(geo, f"{where}:/points", b.points.shape)
    for attr_name, kind, center, source, shape, number in (
            ("displacement", "Vector", "Node", f"{data_file}:/bodies/displacement/{step}", b.points.shape, "Float"),
            ("body", "Scalar", "Cell", f"{where}:/body", b.body.shape, "Int"),
            ("sector", "Scalar", "Cell", f"{where}:/sector", b.sector.shape, "Int")):
        attr = ET.SubElement(grid, "Attribute", Name=attr_name, AttributeType=kind, Center=center)
        data_item(attr, source, shape, number, 8 if number == "Float" else 4)
    return grid


class BodySeriesExport:
    """The rigid bodies with their shapes alone, for a tier without an FE mesh (the lumped tier): the file
    ``path`` (``transient_bodies.xdmf``, the same grid as :class:`FieldSeriesExport`'s companion) with its data in
    ``<path stem>/``: ``bodies.h5`` once and one ``frames_<k>.h5`` per batch of frames (frame k's
    ``bodies/displacement/step_<k>`` [m], the batch's ``time_s`` and ``step``). A frame at t = 0 and at the first
    output at or after each multiple of ``interval_s``; ``write(t, z)``, ``flush()`` and ``close()`` as
    FieldSeriesExport's (``z``: the packed body coordinates ``bodies`` displaces by). ``bodies``: a function
    returning the
    :class:`app.transient.body_shapes.BodyMeshes` (called on rank 0). Kill-safe and resumable as
    FieldSeriesExport."""

    def __init__(self, path: Path, bodies, interval_s: float, comm, resume_from_s: float | None = None,
                 batch_frames: int = FRAMES_PER_FILE):
        self.path = Path(path)
        self.dir = self.path.with_suffix("")
        self.comm = comm
        self.schedule = FrameSchedule(interval_s, 1, interval_periods=1)
        self.interval_s = self.schedule.spacing_s
        self.next_s = 0.0 if resume_from_s is None else self.schedule.next_after(resume_from_s)
        self.batch_frames = max(1, int(batch_frames))
        self.pending: list[tuple[float, np.ndarray | None]] = []
        self.steps: list[bytes] = []
        self.data_files: list[str] = []
        self.bodies = None
        if comm.rank == 0:
            self.bodies = bodies()
            self.dir.mkdir(parents=True, exist_ok=True)
            kept = _steps_until(self.path, resume_from_s) if resume_from_s is not None else []
            self.steps = [step_bytes(step) for step in kept]
            self.data_files = _data_files(kept, self.dir.name)
            for stale in [*self.dir.glob("frames_*.h5*"), *self.dir.glob("step_*.h5*")]:
                if stale.name not in self.data_files:      # frames of a killed run past the checkpoint
                    stale.unlink()
            write_bodies_h5(self.dir / "bodies.h5", self.bodies)
            replace_file(self.path, xdmf_document(self.steps, self.path.stem))
        self.written = comm.bcast(len(self.steps), root=0)
        self.data_files = comm.bcast(self.data_files, root=0)

    def files(self) -> list[str]:
        return [self.path.name, f"{self.dir.name}/bodies.h5"] + [f"{self.dir.name}/{name}" for name in self.data_files]

    def write(self, t: float, body_positions=None) -> None:
        if t < self.next_s - 1e-9 * self.interval_s:
            return
        self.pending.append((float(t), self.bodies.displacement(body_positions) if self.comm.rank == 0 else None))
        self.written += 1
        self.next_s = self.schedule.next_after(t)
        kill_point("fields_written")
        if len(self.pending) >= self.batch_frames:
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames: one HDF5 file, then the XML naming them."""
        if not self.pending:
            return
        frames, self.pending = self.pending, []
        first = self.written - len(frames)
        name = f"frames_{first:06d}.h5"
        if self.comm.rank == 0:
            steps = [f"step_{k:06d}" for k in range(first, first + len(frames))]
            datasets, attrs = batch_index(first, [t for t, _ in frames])
            datasets.update({f"bodies/displacement/{step}": u for step, (_, u) in zip(steps, frames)})
            attrs["bodies/displacement"] = {"units": "m"}
            write_h5_atomic(self.dir / name, datasets, attrs)
            kill_point("fields_data")
            self.steps += [step_bytes(body_grid(self.bodies, t, self.dir.name, f"{self.dir.name}/{name}", step))
                           for step, (t, _) in zip(steps, frames)]
            replace_file(self.path, xdmf_document(self.steps, self.path.stem))
        self.data_files.append(name)

    def close(self) -> None:
        """Write the buffered frames; nothing stays open between outputs."""
        self.flush()


def batch_index(first: int, times) -> tuple[dict, dict]:
    """The datasets and attributes that index a batch file (frames ``first``, ``first + 1``, ...at ``times`` [s]):
    ``time_s`` and ``step`` (frame k's values are the datasets ``<field>/step_<k>``), as write_h5_atomic takes
    them."""
    n = len(times)
    return ({"time_s": np.asarray(times, dtype=float), "step": np.arange(first, first + n, dtype=np.int64)},
            {"time_s": {"units": "s"},
             "step": {"meaning": "frame index k of each time: the frame's values are <field>/step_<k> (k in 6 "
                                 "digits)"}})


def _data_files(steps: list[ET.Element], folder: str) -> list[str]:
    """The names of the files in ``folder`` that the HDF5 DataItems of ``steps`` name, in order of first use."""
    names: dict[str, None] = {}
    for step in steps:
        for item in step.iter("DataItem"):
            if item.get("Format") == "HDF":
                where = Path(item.text.strip().split(":", 1)[0])
                if where.parent.name == folder and where.name not in ("mesh.h5", "bodies.h5", "contact_sites.h5"):
                    names[where.name] = None
    return list(names)


def _kept_peaks(out_dir: Path, steps: list[ET.Element]) -> dict:
    """The running peaks of the frames kept on resume (rank 0): the merge of each frame's own (the attribute
    FRAME_PEAKS of the displacement the step names)."""
    import h5py

    from app.fe.derived import merge_peaks

    peaks: dict = {}
    batches: dict[str, dict] = {}         # a batch file's peaks by frame (its root attribute), read once
    for step in steps:
        source = attribute_source(step, "displacement")
        if source is None:
            continue
        frame = None
        try:
            if source[0] not in batches:
                with h5py.File(out_dir / source[0], "r") as f:
                    batches[source[0]] = json.loads(f.attrs.get(FRAME_PEAKS, "{}"))
            frame = batches[source[0]].get(source[1].rsplit("/", 1)[-1])
            if frame is None:             # an older layout: the frame's group step_<k>, peaks on its displacement
                with h5py.File(out_dir / source[0], "r") as f:
                    older = f[source[1]].attrs.get(FRAME_PEAKS)
                frame = json.loads(older) if older is not None else None
        except (OSError, KeyError):
            frame = None
        if frame is not None:
            merge_peaks(peaks, frame)
    return peaks


def attribute_source(step: ET.Element, name: str) -> tuple[str, str] | None:
    """(file relative to the XML's directory, dataset path) of the HDF5 DataItem of a step's attribute ``name``."""
    for attr in step.iter("Attribute"):
        if attr.get("Name") == name:
            item = attr.find("DataItem")
            if item is not None and item.get("Format") == "HDF":
                where, path = item.text.strip().split(":", 1)
                return where, path
    return None


def read_frames(path: Path, names=("displacement", "potential")) -> list[tuple[float, dict[str, np.ndarray]]]:
    """The frames of a field series ``path`` (an XDMF file of these writers), as ParaView and meshio see them:
    [(time, {attribute name: values})] for the node/cell attributes ``names`` of every step, read where its
    DataItem points (any layout: a file per batch or, from older runs, a file per frame)."""
    import h5py

    path = Path(path)
    frames, files = [], {}
    try:
        for step in ET.parse(path).getroot().find("Domain/Grid").findall("Grid"):
            values = {}
            for name in names:
                source = attribute_source(step, name)
                if source is None:
                    continue
                if source[0] not in files:
                    files[source[0]] = h5py.File(path.parent / source[0], "r")
                values[name] = files[source[0]][source[1]][()]
            frames.append((float(step.find("Time").get("Value")), values))
    finally:
        for f in files.values():
            f.close()
    return frames


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
