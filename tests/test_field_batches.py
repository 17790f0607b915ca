"""The field series written in batches (app/transient/fields.py FieldSeriesExport): the batched series is the
per-frame one (times, values, peaks), and a process killed inside a batch, after a checkpoint, and resumed
from that checkpoint leaves the series of a run in one go.

Reference: the frames' values formed directly, V q_k for each frame k on its own (the modal tier's expansion),
and the writer with one frame per batch (the old layout's one file per frame). A fake vertex basis on a
2 x 3 quad mesh stands in for the reduced model, so each test takes well under a second (the physics of the
expansion is tests/test_modal_checkpoint.py's: the written field equals the time series' tip displacement).
Tolerance: the batched product V Q and the per-frame V q_k sum the same terms, in an order BLAS may choose per
call, so 1e-13 of the field's largest value (round-off of 6 terms); a resumed run cuts its batches where the run
in one go does (at the checkpoint), so there: bit for bit."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from app.transient.fields import FRAME_PEAKS, FieldSeriesExport, FrameSchedule, read_frames

PERIOD_S = 1e-4
FRAMES = 11
MODES = 6


class FakeBasis:
    """The vertex-values interface of the modal tier (app/reduced/engine.py ReducedVertexFields) on a 3 x 4
    vertex quad mesh: values = V q, a 'von Mises' field |u| and its peak per region. ``expand=False``: the FE
    tier's interface (``sample`` per frame, no ``expand``)."""

    def __init__(self, expand: bool = True):
        rng = np.random.default_rng(7)
        x, y = np.meshgrid(np.arange(4.0), np.arange(3.0))
        self.comm = MPI.COMM_SELF
        self.n_nodes, self.n_cells = 12, 6
        ids = np.arange(12).reshape(3, 4)
        cells = np.array([[ids[j, i], ids[j, i + 1], ids[j + 1, i + 1], ids[j + 1, i]]
                          for j in range(2) for i in range(3)], dtype=np.int64)
        self.mesh_arrays = {"geometry": np.column_stack([x.ravel(), y.ravel(), np.zeros(12)]) * 1e-3,
                            "topology": cells, "region": np.array([1, 1, 1, 2, 2, 2], dtype=np.int32)}
        self.topology_type = "Quadrilateral"
        self.region_names = {1: "horn", 2: "piezo"}
        self.derived = ("von_mises",)
        self.basis = rng.standard_normal((4 * 12, MODES)) * 1e-6
        if expand:
            self.expand = self._expand

    def _frame(self, values: np.ndarray):
        u, phi = values[:36].reshape(12, 3), values[36:]
        vm = np.linalg.norm(u, axis=1) * 1e11
        peaks = {"horn": {"von_mises_Pa": float(vm[:8].max())}, "piezo": {"von_mises_Pa": float(vm[4:].max())}}
        return u, phi, {"von_mises_Pa": vm}, peaks

    def _expand(self, q: np.ndarray):
        values = self.basis @ q
        return [self._frame(values[:, k]) for k in range(q.shape[1])]

    def sample(self, q):
        u, phi, _, _ = self._frame(self.basis @ q)
        return u, phi

    def derived_frame(self, q):
        _, _, fields, peaks = self._frame(self.basis @ q)
        return fields, peaks


def coordinates(k: int) -> np.ndarray:
    return np.cos(np.arange(1, MODES + 1) * (0.7 * k + 0.3))


def scenario(out: Path, batch_frames: int, checkpoints=(), resume_from: int | None = None, expand: bool = True,
             frames=range(FRAMES), thread: bool = False) -> FieldSeriesExport:
    """Frames ``frames`` at t = k PERIOD_S of coordinates(k) and a 'checkpoint' after the frames in
    ``checkpoints`` as the run loop makes one (app/loop/loop.py: ``flush()`` unless the buffer rides in the
    checkpoint, then the export's ``checkpoint_record()``, saved as ``out/checkpoint.json`` and its arrays as
    ``out/checkpoint.npz``); resumed after frame ``resume_from`` from that record; closed at the end. ``thread``:
    the modal tier's batches written by the writer thread (FieldSeriesExport ``writer_thread``), as in a run."""
    state = {"q": None}
    vertex = FakeBasis(expand)
    export = FieldSeriesExport(out / "transient_fields.xdmf", vertex, lambda: state["q"],
                               FrameSchedule(PERIOD_S, 1, interval_periods=1),
                               resume_from_s=None if resume_from is None else resume_from * PERIOD_S,
                               batch_frames=batch_frames, writer_thread=thread)
    if resume_from is not None:
        with np.load(out / "checkpoint.npz") as saved:
            export.resume(json.loads((out / "checkpoint.json").read_text()), dict(saved))
    for k in frames:
        state["q"] = coordinates(k)
        export.write(k * PERIOD_S)
        if k in checkpoints:
            if not export.carries:
                export.flush()
            record, arrays = export.checkpoint_record()
            np.savez(out / "checkpoint.npz", **arrays)
            (out / "checkpoint.json").write_text(json.dumps(record))
    export.close()
    return export


def test_batched_series_equals_the_per_frame_series(tmp_path):
    """Times, displacement, potential and the derived field of every frame, read back through the XML (the
    writer's reader and meshio's TimeSeriesReader), against V q_k formed frame by frame; the batched writer's
    against the one-frame-per-batch writer's; and the frame files are the batches."""
    vertex = FakeBasis()
    expected = [vertex._frame(vertex.basis @ coordinates(k)) for k in range(FRAMES)]
    scale = max(np.abs(e[0]).max() for e in expected)
    series = {}
    for name, batch, expand, checkpoints, thread in (("per_frame", 1, True, (), False),
                                                     ("batched", 4, True, (5,), True),
                                                     ("fe_batched", 4, False, (5,), False)):
        out = tmp_path / name
        export = scenario(out, batch, checkpoints, expand=expand, thread=thread)
        frames = read_frames(out / "transient_fields.xdmf", ("displacement", "potential", "von_mises_Pa"))
        assert [t for t, _ in frames] == [k * PERIOD_S for k in range(FRAMES)]
        for (_, values), (u, phi, derived, _) in zip(frames, expected):
            assert np.abs(values["displacement"] - u).max() <= 1e-13 * scale
            assert np.abs(values["potential"] - phi).max() <= 1e-13 * scale
            np.testing.assert_allclose(values["von_mises_Pa"], derived["von_mises_Pa"], rtol=1e-12)
        series[name] = frames
        files = sorted(p.name for p in (out / "transient_fields").glob("frames_*"))
        assert files == sorted(export.data_files) == sorted(f.split("/")[1] for f in export.files()
                                                            if "/frames_" in f)
        # meshio reads the batched layout: the same times and values
        with meshio.xdmf.TimeSeriesReader(out / "transient_fields.xdmf") as reader:
            points, _ = reader.read_points_cells()
            assert reader.num_steps == FRAMES
            for k in range(FRAMES):
                t, point_data, _ = reader.read_data(k)
                assert t == k * PERIOD_S
                np.testing.assert_array_equal(point_data["displacement"], frames[k][1]["displacement"])
    # one frame per file; batches of 4, the modal tier's (its buffer rides in the checkpoint after frame 5):
    # frames 0-3, 4-7, 8-10; the FE tier's, cut at that checkpoint: 0-3, 4-5, 6-9, 10
    assert sorted(p.name for p in (tmp_path / "per_frame" / "transient_fields").glob("frames_*")) == [
        f"frames_{k:06d}.h5" for k in range(FRAMES)]
    assert sorted(p.name for p in (tmp_path / "batched" / "transient_fields").glob("frames_*")) == [
        "frames_000000.h5", "frames_000004.h5", "frames_000008.h5"]
    assert sorted(p.name for p in (tmp_path / "fe_batched" / "transient_fields").glob("frames_*")) == [
        "frames_000000.h5", "frames_000004.h5", "frames_000006.h5", "frames_000010.h5"]
    for (_, a), (_, b) in zip(series["batched"], series["fe_batched"]):
        for name in a:
            assert np.abs(a[name] - b[name]).max() <= 1e-13 * np.abs(b[name]).max()


def test_bodies_of_a_batch_are_each_frames_own(tmp_path):
    """The rigid bodies' companion (transient_bodies.xdmf) of a modal series, its batches displaced at once
    (app/transient/body_shapes.py BodyMeshes.displacements, on the writer thread): frame k's displacement, read
    back through the XML, is that of its own coordinates z_k. Reference by hand: a ball translated by z_k moves
    every vertex by z_k (round-off of the reference position, 1e-18 m)."""
    from app.transient.body_shapes import BodyMeshes, sphere_shape

    meshes = BodyMeshes.from_shapes([("ball", (0.0, 0.0, 0.0), [], [sphere_shape(1e-3)])], 3, "3d",
                                    {"ball": slice(0, 3)})
    state = {"q": None}
    export = FieldSeriesExport(tmp_path / "transient_fields.xdmf", FakeBasis(), lambda: state["q"],
                               FrameSchedule(PERIOD_S, 1, interval_periods=1), bodies=lambda size: meshes,
                               batch_frames=4, writer_thread=True)
    shifts = [np.array([1e-4 * k, -2e-5 * k, 3e-6 * k * k]) for k in range(FRAMES)]
    for k in range(FRAMES):
        state["q"] = coordinates(k)
        export.write(k * PERIOD_S, body_positions=shifts[k])
    export.close()
    frames = read_frames(tmp_path / "transient_bodies.xdmf", ("displacement",))
    assert [t for t, _ in frames] == [k * PERIOD_S for k in range(FRAMES)]
    for (_, values), shift in zip(frames, shifts):
        np.testing.assert_allclose(values["displacement"], np.tile(shift, (len(meshes.points), 1)), rtol=0,
                                   atol=1e-18)


KILL_SCRIPT = """
import sys
from pathlib import Path
sys.path.insert(0, {tests!r})
import test_field_batches as t
t.scenario(Path({out!r}), batch_frames={batch}, checkpoints=(4,), expand={expand}, thread={thread})
"""


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives a serial subprocess")
@pytest.mark.parametrize("point, named, batch, resumed_batch, expand, thread", [
    ("fields_written:9", 6, 3, 3, True, False), ("fields_data:3", 6, 3, 3, True, False),
    ("fields_written:10", 8, 2, 3, True, False), ("fields_written:9", 8, 3, 3, False, False),
    ("fields_data:3", 5, 3, 3, False, False),
    ("fields_written:9", 6, 3, 3, True, True), ("fields_data:3", 6, 3, 3, True, True),
    ("fields_written:10", 8, 2, 3, True, True)])
def test_killed_inside_a_batch_resumes_to_the_one_go_series(tmp_path, point, named, batch, resumed_batch, expand,
                                                            thread):
    """A process SIGKILLed (app/killpoint.py) after the 'checkpoint' at frame 4. The modal tier's buffer rides in
    the checkpoint (frames 3 and 4 buffered there in batches of 3): killed with frames 6-8 buffered
    (``fields_written:9``: 0-5 on disk, frames 3-5 of the batch after the checkpoint too), or with the batch 6-8
    written and not yet named by the XML (``fields_data:3``), or in batches of 2 with frames 0-7 on disk and 8 and
    9 buffered (``fields_written:10``), resumed in batches of 3. The FE tier's flushes before the checkpoint
    (batches 0-2, 3-4, 5-7, ...): killed with frame 8 buffered, or with the batch 5-7 written and not named. The
    XML names only complete files (``named`` frames); resumed from the checkpoint (its record) the series is the
    one-go series (values, times, peaks): bit for bit when the resumed run cuts its batches as the killed one
    did, else to round-off (another cut of the batches), and the folder holds exactly the files the XML names
    (e.g. the killed run's frames_000003.h5, with frames after the checkpoint, removed). ``thread``: the modal
    tier's batches written by the writer thread, as in a run (killed and resumed so): the writer may lag behind
    the frames taken, so at ``fields_written`` the XML names up to ``named`` frames, whole batches (the batches
    it had not written at the checkpoint ride in it and are written again on resume); at ``fields_data`` (inside
    the writer) exactly ``named``."""
    one_go = scenario(tmp_path / "one_go", batch_frames=resumed_batch, checkpoints=(4,), expand=expand,
                      thread=thread)
    out = tmp_path / "killed"
    env = {**os.environ, "PIEZODYN_KILL_AT": point}
    script = KILL_SCRIPT.format(tests=str(Path(__file__).parent), out=str(out), batch=batch, expand=expand,
                                thread=thread)
    killed = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                            cwd=Path(__file__).parents[1])
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    left = read_frames(out / "transient_fields.xdmf")           # every file the XML names is complete
    if thread and point.startswith("fields_written"):
        assert len(left) <= named and len(left) % batch == 0
    else:
        assert len(left) == named
    resumed = scenario(out, batch_frames=resumed_batch, checkpoints=(4,), resume_from=4, frames=range(5, FRAMES),
                       expand=expand, thread=thread)
    names = ("displacement", "potential", "von_mises_Pa")
    a, b = read_frames(tmp_path / "one_go" / "transient_fields.xdmf", names), read_frames(
        out / "transient_fields.xdmf", names)
    assert [t for t, _ in a] == [t for t, _ in b]
    for (_, x), (_, y) in zip(a, b):
        for name in names:
            if batch == resumed_batch:
                np.testing.assert_array_equal(x[name], y[name])
            else:
                assert np.abs(x[name] - y[name]).max() <= 1e-13 * np.abs(x[name]).max()
    assert sorted(resumed.peaks) == sorted(one_go.peaks) == ["horn", "piezo"]
    for region, peaks in one_go.peaks.items():
        assert resumed.peaks[region] == pytest.approx(peaks, rel=0 if batch == resumed_batch else 1e-13)
    assert resumed.written == FRAMES
    # no file of the killed run left over: the folder holds the mesh and the frame files the XML names
    assert sorted(p.name for p in (out / "transient_fields").iterdir()) == sorted(["mesh.h5", *resumed.data_files])
    if batch == resumed_batch:
        assert resumed.data_files == one_go.data_files
    # each frame keeps its own peaks (what a resumed run merges)
    import h5py

    with h5py.File(out / "transient_fields" / resumed.data_files[1], "r") as f:
        assert "step_000003" in json.loads(f.attrs[FRAME_PEAKS])


def test_batch_file_layout_and_a_resumed_series_of_the_older_layout(tmp_path):
    """A batch file (app/transient/fields.py): one group per field with frame k's values as ``step_<k>`` and the
    units as the group's attribute, the frames' times and indices (``time_s``, ``step``) and their peaks
    (``region_peaks_json``, by frame) once per file; and a series written in the layout before it (a group
    ``step_<k>`` per frame, ``units``, ``time_s`` and the frame's peaks as attributes of its datasets), resumed
    after frame 6: the resumed export's running peaks are those of frames 0-6, read from the older files."""
    import re

    import h5py

    from app.fe.derived import merge_peaks

    out = tmp_path / "series"
    scenario(out, batch_frames=4, thread=True)
    vertex = FakeBasis()
    expected = [vertex._frame(vertex.basis @ coordinates(k))[3] for k in range(FRAMES)]
    with h5py.File(out / "transient_fields" / "frames_000004.h5", "r") as f:
        assert sorted(f) == ["displacement", "potential", "step", "time_s", "von_mises_Pa"]
        assert f["step"][()].tolist() == [4, 5, 6, 7]
        assert f["time_s"][()].tolist() == [k * PERIOD_S for k in range(4, 8)]
        assert f["displacement"].attrs["units"] == "m" and f["potential"].attrs["units"] == "V"
        assert sorted(f["displacement"]) == [f"step_{k:06d}" for k in range(4, 8)]
        assert f["displacement/step_000005"].shape == (12, 3) and not f["displacement/step_000005"].attrs
        peaks = json.loads(f.attrs[FRAME_PEAKS])       # the batch's product against frame by frame: round-off
        assert sorted(peaks) == [f"step_{k:06d}" for k in range(4, 8)]
        for k in range(4, 8):
            for region, values in expected[k].items():
                assert peaks[f"step_{k:06d}"][region] == pytest.approx(values, rel=1e-13)
    written = {}
    # the same series in the older layout: the files rewritten, the XML's paths with them
    for path in sorted((out / "transient_fields").glob("frames_*.h5")):
        with h5py.File(path, "r") as f:
            frames = {int(k): float(t) for k, t in zip(f["step"][()], f["time_s"][()])}
            values = {(name, k): f[f"{name}/step_{k:06d}"][()] for name in ("displacement", "potential",
                                                                          "von_mises_Pa") for k in frames}
            peaks = json.loads(f.attrs[FRAME_PEAKS])
        written.update(peaks)
        with h5py.File(path, "w") as f:
            for (name, k), v in values.items():
                ds = f.create_dataset(f"step_{k:06d}/{name}", data=v)
                if name == "displacement":
                    ds.attrs.update({"units": "m", "time_s": frames[k],
                                     FRAME_PEAKS: json.dumps(peaks[f"step_{k:06d}"])})
    xml = out / "transient_fields.xdmf"
    xml.write_text(re.sub(r":/(\w+)/(step_\d+)<", r":/\2/\1<", xml.read_text()))
    assert len(read_frames(xml)) == FRAMES
    resumed = FieldSeriesExport(xml, vertex, lambda: None, FrameSchedule(PERIOD_S, 1, interval_periods=1),
                                resume_from_s=6 * PERIOD_S, batch_frames=4)
    kept = {}
    for k in range(7):
        merge_peaks(kept, written[f"step_{k:06d}"])
    assert resumed.peaks == kept and resumed.written == 7


@pytest.mark.parametrize("plane", [False, True])
def test_modal_expansion_of_a_batch_equals_frame_by_frame(plane):
    """app/reduced/engine.py ReducedVertexFields: ``expand`` of a batch of coordinates (one product of each basis
    with all the columns, the derived fields and peaks of all the frames at once) against ``sample`` and
    ``derived_frame`` of each column alone (the per-frame path, every component formed), on random bases over
    the 2 x 3 quad mesh with a piezoelectric region (so principal stresses and |E| enter the peaks). ``plane``: the
    bases of a model of revolution, components zero for every basis vector (u_y, the potential of a metal part,
    the shears yz and xy, E_y), which ``expand`` does not form (one third fewer products) and puts back as
    zeros. Tolerance 1e-13 of each field's largest value: the same sums in another BLAS call (gemm against
    gemv), the principal stresses of the batch component by component against those of the frame's tensors."""
    from types import SimpleNamespace

    from app.fe.derived import RAW, RAW_COLUMNS, RegionAveraging
    from app.reduced.engine import ReducedVertexFields

    rng = np.random.default_rng(11)
    mesh = FakeBasis().mesh_arrays
    pairs = RegionAveraging(mesh["topology"], mesh["region"], 12, [2]).size
    vertex_basis = rng.standard_normal((48, MODES))
    derived_basis = rng.standard_normal((pairs, RAW_COLUMNS, MODES)) * 1e6
    if plane:
        vertex_basis[1:36:3] = 0.0                  # u_y
        vertex_basis[36:42] = 0.0                   # the potential of vertices 0-5 (the horn's bottom rows)
        stress, field = RAW["stress"].start, RAW["electric_field"].start
        derived_basis[:, [stress + 3, stress + 5, field + 1]] = 0.0
    model = SimpleNamespace(vertex_basis=vertex_basis,
                            derived_basis=derived_basis.reshape(pairs * RAW_COLUMNS, MODES),
                            region_table=np.array(["1|horn|0", "2|piezo|1"]), mesh_geometry=mesh["geometry"],
                            mesh_topology=mesh["topology"], mesh_region=mesh["region"],
                            mesh_topology_type="Quadrilateral")
    vertex = ReducedVertexFields(model, MPI.COMM_SELF, ("von_mises", "principal_stress", "electric_field", "stress"))
    q = rng.standard_normal((MODES, 5))
    batch = vertex.expand(q)
    assert len(batch) == 5
    for k, (u, phi, fields, peaks) in enumerate(batch):
        u1, phi1 = vertex.sample(q[:, k])
        fields1, peaks1 = vertex.derived_frame(q[:, k])
        for a, b in ((u, u1), (phi, phi1), *((fields[name], fields1[name]) for name in fields1)):
            assert a.shape == b.shape and np.abs(a - b).max() <= 1e-13 * np.abs(b).max()
        assert sorted(fields) == sorted(fields1) == ["electric_field_V_per_m", "principal_stress_Pa", "stress_Pa",
                                                     "von_mises_Pa"]
        assert sorted(peaks) == sorted(peaks1) == ["horn", "piezo"]
        assert sorted(peaks["piezo"]) == ["electric_field_V_per_m", "max_principal_stress_Pa", "von_mises_Pa"]
        for region, values in peaks1.items():
            assert peaks[region] == pytest.approx(values, rel=1e-13)
        if plane:
            assert not u[:, 1].any() and not phi[:6].any() and not fields["stress_Pa"][:, [3, 5]].any()
            assert not fields["electric_field_V_per_m"][:, 1].any()
    formed = 4 + 2 if plane else 6 + 3              # stress and E components in the derived product
    assert vertex._derived_T.shape == (MODES, formed * pairs)


def test_fast_hdf5_writer_reads_back_as_h5py_high_level(tmp_path):
    """app/files.py write_h5_atomic (h5py's low-level API for numeric arrays and float/int/str attributes) against
    the same file written with h5py's high-level API: the same datasets, values, dtypes and attributes (str read
    back as str, lists through the high level)."""
    import h5py

    from app.files import write_h5_atomic

    rng = np.random.default_rng(5)
    datasets = {"step_000003/displacement": rng.standard_normal((7, 3)),
                "step_000003/potential": rng.standard_normal(7),
                "mesh/in_region_1": (rng.uniform(size=9) > 0.5).astype(np.int8),
                "mesh/topology": np.arange(12).reshape(3, 4), "names": np.array(["a", "bc"], dtype=object)}
    attrs = {"step_000003/displacement": {"units": "m", "time_s": 2.5e-4, "region_peaks_json": '{"horn": {"x": 1}}'},
             "mesh/in_region_1": {"name": "region: horn", "tag": 3}, "mesh/topology": {"names": ["ab", "c"]}}
    write_h5_atomic(tmp_path / "fast.h5", datasets, attrs)
    with h5py.File(tmp_path / "slow.h5", "w") as f:
        for name, values in datasets.items():
            ds = f.create_dataset(name, data=values)
            for key, value in attrs.get(name, {}).items():
                ds.attrs[key] = value
    assert not list(tmp_path.glob("*.tmp"))
    with h5py.File(tmp_path / "fast.h5", "r") as a, h5py.File(tmp_path / "slow.h5", "r") as b:
        names = []
        a.visit(names.append)
        other = []
        b.visit(other.append)
        assert names == other
        for name in datasets:
            assert a[name].dtype == b[name].dtype and a[name].shape == b[name].shape
            assert np.array_equal(a[name][()], b[name][()])
            assert sorted(a[name].attrs) == sorted(b[name].attrs)
            for key in b[name].attrs:
                x, y = a[name].attrs[key], b[name].attrs[key]
                assert type(x) is type(y) and np.array_equal(x, y), (name, key)


@pytest.mark.parametrize("schedule", [
    FrameSchedule(1 / 20100.0, 8, interval_periods=16), FrameSchedule(PERIOD_S, 1, interval_periods=1),
    FrameSchedule(1 / 20100.0, 4, interval_periods=2.5), FrameSchedule(1e-4, 3, burst_times_s=[0.0, 2.5e-4, 2.6e-4])],
    ids=["bursts", "every_period", "fractional_interval", "burst_times"])
def test_upcoming_frame_times_are_the_next_after_chain(schedule):
    """FrameSchedule.upcoming (the frame times the modal kernel is given, app/reduced/kernel.py Frames) against
    the loop's rule, next_after applied again and again from a frame time: the same floats (rtol 0: the kernel
    compares step times with them as the loop does), from t = 0 and from a frame far into the run (burst 1000:
    the burst index from a division that rounds)."""
    for start in (schedule.frames[0], schedule.next_after(1000 * (schedule.interval_s or 0.0) - 1e-12)):
        chain = [start]
        while len(chain) < 40 and math.isfinite(chain[-1]):
            chain.append(schedule.next_after(chain[-1]))
        chain = [t for t in chain if math.isfinite(t)]
        assert schedule.upcoming(start, 40).tolist() == chain
        assert schedule.upcoming(start, 5).tolist() == chain[:5]
    assert schedule.ordered


def test_overlapping_bursts_are_not_ordered():
    """Bursts longer than their interval (an interval of half a period): next_after looks at two bursts only, so
    the kernel does not take such frames (FieldSeriesExport.engine_can_take)."""
    assert not FrameSchedule(1e-4, 8, interval_periods=0.5).ordered


def test_a_checkpoint_record_of_the_older_format_resumes(tmp_path):
    """A checkpoint of the version that listed the buffered frames' coordinates in its JSON record
    (``buffered``: t_s, q, z) resumes as one with them in its arrays: the series of the run in one go, bit for
    bit (the same batches)."""
    one_go = tmp_path / "one_go"
    scenario(one_go, batch_frames=3, checkpoints=(4,))
    out = tmp_path / "older"
    scenario(out, batch_frames=3, checkpoints=(4,), frames=range(5))
    record = json.loads((out / "checkpoint.json").read_text())
    with np.load(out / "checkpoint.npz") as saved:
        q = saved["fields_buffered_q"]
    assert len(record["buffered_s"]) == 2                      # frames 3 and 4 rode in the checkpoint
    older = {"on_disk": record["on_disk"], "buffered": [{"t_s": t, "q": q[k].tolist(), "z": None}
                                                        for k, t in enumerate(record["buffered_s"])]}
    (out / "checkpoint.json").write_text(json.dumps(older))
    np.savez(out / "checkpoint.npz")
    scenario(out, batch_frames=3, checkpoints=(), resume_from=4, frames=range(5, FRAMES))
    names = ("displacement", "potential", "von_mises_Pa")
    a, b = read_frames(one_go / "transient_fields.xdmf", names), read_frames(out / "transient_fields.xdmf", names)
    assert [t for t, _ in a] == [t for t, _ in b] == [k * PERIOD_S for k in range(FRAMES)]
    for (_, x), (_, y) in zip(a, b):
        for name in names:
            np.testing.assert_array_equal(x[name], y[name])


def test_region_peaks_from_chosen_columns_and_any_pair_order():
    """app/fe/derived.py frame_region_peaks on the raw columns raw_columns chooses (stress and E for these
    fields), with the quantities whose maxima the peaks are passed in (``known``: von Mises, the largest principal
    stress, |E| at every pair, no values), and on the pairs in another order (a region's pairs not consecutive:
    indices instead of a slice), against the 18-column call on pairs ordered by region: the same peaks exactly
    (maxima of the same values)."""
    from types import SimpleNamespace

    from app.fe.derived import RAW_COLUMNS, frame_region_peaks, node_fields, raw_columns

    rng = np.random.default_rng(3)
    values = rng.standard_normal((4, 30, RAW_COLUMNS)) * 1e6
    pair_region = np.repeat([1, 2, 5], [8, 12, 10])
    regions = [SimpleNamespace(tag=1, name="horn", e=None), SimpleNamespace(tag=2, name="piezo", e=True),
               SimpleNamespace(tag=5, name="stem", e=None)]
    reference = frame_region_peaks(values, pair_region, regions)
    names = ("von_mises", "principal_stress")
    indices, columns = raw_columns(names, electric=True)
    assert indices.tolist() == list(range(6, 15))
    chosen = values[..., indices]
    fields = {key: v.reshape(4, 30, *v.shape[1:])
              for key, v in node_fields(chosen.reshape(120, -1), names, columns=columns).items()}
    known = {"von_mises_Pa": fields["von_mises_Pa"], "max_principal_stress_Pa": fields["principal_stress_Pa"][..., 0],
             "electric_field_V_per_m": np.linalg.norm(chosen[..., columns["electric_field"]], axis=-1)}
    order = rng.permutation(30)
    for peaks in (frame_region_peaks(chosen, pair_region, regions, columns),
                  frame_region_peaks(None, pair_region, regions, known=known),
                  frame_region_peaks(chosen[:, order], pair_region[order], regions, columns),
                  frame_region_peaks(None, pair_region[order], regions,
                                     known={k: v[:, order] for k, v in known.items()})):
        assert peaks == reference
    assert sorted(reference[0]["piezo"]) == ["electric_field_V_per_m", "max_principal_stress_Pa", "von_mises_Pa"]
