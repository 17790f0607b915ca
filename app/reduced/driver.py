"""The ``transient`` analysis in the modal tier: the same case as the FE tier, run reduced.

Case -> FE model (mesh, forms, electrodes) -> Craig-Bampton basis (interface = the FE nodes the
case's contacts touch; driven electrodes as input coordinates) -> the compiled loop of
:mod:`app.reduced.kernel` with the case's rigid bodies, contacts, loads, drive, step sizes and
scheme -> the time series under the FE tier's names (``transient.h5``) and its statistics.

Loads and drive as in the FE tier: gravity and the downforce act on the transducer like its mass
(projected onto the basis), the drive U(t) = V sin(wt) from rest or V cos(wt) from the harmonic
steady state (here the reduced model's own steady state), V from ``tip_amplitude_m`` by a reduced
harmonic solve. Surface contacts are frictionless node sets with lumped areas (app.reduced.surface).
Checkpoints and ``--resume`` as in the FE tier (app/reduced/restart.py); the FE fields (x = T q) to XDMF
at the output interval only. Not yet in this tier: friction (the motor has its own loop:
app/reduced/motor.py).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from app import series as S
from app.errors import CaseError, NumericalFailure
from app.killpoint import kill_point
from app.loop.checkpoint import POINTER, CellLayout, CheckpointWriter, case_digest, mark_started, read_checkpoint
from app.reduced import kernel as kr
from app.reduced import restart
from app.reduced.craig_bampton import ReducedBasis, harmonic_response, reduce_model
from app.reduced.surface import SURFACE_KEYS, SurfaceContactSpec, kernel_surface_arrays, surface_nodes
from app.series import TimeSeriesWriter
from app.transient.driver import plot_spec
from app.transient.fields import FieldSeriesExport

ROWS_PER_CHUNK = 20000
# a field output is due at the first step with t >= next output time - this fraction of the
# interval (app.transient.fields.FieldSeriesExport.write, the FE tier's rule)
FIELD_TIME_TOLERANCE = 1e-9


class ReducedScene:
    """Everything the compiled loop needs, as arrays, built from a case. ``restore(model, layout)``
    (a resumed run) returns the checkpoint's :class:`app.reduced.restart.SavedModel`: its reduced
    model and basis are used instead of reducing again."""

    def __init__(self, case, comm, log, restore=None):
        from app.fe.model import build_model
        from app.fe.operators import assemble_operators

        self.case, self.comm, self.log = case, comm, log
        self.cfg = cfg = case.transient
        file = case.source
        model = self.model = build_model(case, comm)
        self.layout = CellLayout(model.W)
        self.gdim = gdim = model.mesh.geometry.dim
        if model.electrodes_of("floating"):
            raise CaseError(file, "electrodes", "floating electrodes are not supported by the transient analysis")
        self.drive_point = cfg.drive.point if cfg.drive.point in case.points else None
        if cfg.drive.tip_amplitude_m is not None and self.drive_point is None:
            raise CaseError(file, "transient.drive.point", f"unknown point {cfg.drive.point!r}")
        self.names = {"bodies": [b.name for b in cfg.bodies], "contacts": [c.name for c in cfg.contacts]}
        body_index = {name: i for i, name in enumerate(self.names["bodies"])}

        # interface: the FE node of every node contact (its displacement DOFs along the normal), then
        # every displacement DOF of the nodes of every surface contact
        nodes = []
        interface: list[int] = []
        for i, c in enumerate(cfg.contacts):
            if c.kind != "node":
                continue
            key = f"transient.contacts[{i}]"
            if c.node_point not in case.points:
                raise CaseError(file, f"{key}.node_point", f"unknown point {c.node_point!r} (see [points])")
            normal = np.asarray(c.normal, dtype=float)
            if normal.size != gdim or not math.isclose(np.linalg.norm(normal), 1.0, rel_tol=1e-9):
                raise CaseError(file, f"{key}.normal", f"must be a unit vector with {gdim} components")
            x_node, dofs = _node_dofs(model, np.asarray(case.points[c.node_point].coordinates_m, dtype=float))
            coords = []
            for k in range(gdim):
                if normal[k] != 0.0 and dofs[k] >= 0:
                    if dofs[k] not in interface:
                        interface.append(dofs[k])
                    coords.append(interface.index(dofs[k]))
                else:
                    coords.append(-1)
            if all(j < 0 for j in coords):
                raise CaseError(file, f"{key}.node_point", "the node has no free displacement DOF along the normal")
            nodes.append((c, x_node, coords))
        surfaces = self._surface_contacts(interface, body_index)

        fixed = np.concatenate([model.support_dofs, model.grounded_dofs]
                               + [model.electrode_dofs[n] for n in model.electrodes_of("ground")])
        electrodes = {n: model.electrode_dofs[n] for n in model.electrodes_of("voltage")}
        red = case.reduction
        self.cutoff_Hz = red.cutoff_Hz if red.cutoff_Hz is not None else (
            None if red.n_modes is not None else red.cutoff_factor * cfg.drive.frequency_Hz)
        gravity = np.asarray(cfg.loads.gravity_m_per_s2 or [0.0] * gdim, dtype=float)
        force = np.asarray(cfg.loads.fe_force_N or [0.0] * gdim, dtype=float)
        for key, value in (("gravity_m_per_s2", gravity), ("fe_force_N", force)):
            if value.size != gdim:
                raise CaseError(file, f"transient.loads.{key}", f"needs {gdim} components")
        start = time.perf_counter()
        self.saved = saved = restore(model, self.layout) if restore is not None else None
        if saved is not None:
            if saved.electrodes != list(electrodes) or saved.K.shape[0] < len(interface) + len(electrodes):
                raise CaseError(file, "reduction", "the checkpoint's reduced model does not fit this case")
            self.basis = ReducedBasis(saved.K, saved.M, saved.C, np.array(interface, dtype=np.int64),
                                      saved.electrodes, saved.mode_frequencies_Hz, saved.charge_rows,
                                      saved.columns, comm)
            self.fq = saved.fq
        else:
            damping_Hz = case.damping.reference_frequency_Hz or cfg.drive.frequency_Hz
            ops = assemble_operators(model, damping_frequency_Hz=damping_Hz)
            self.basis = reduce_model(ops.K, ops.M, ops.C, model.W, fixed, np.array(interface, dtype=np.int64),
                                      electrodes, n_modes=red.n_modes, cutoff_Hz=self.cutoff_Hz,
                                      n_enrich=red.enrich_modes, enrich_near_Hz=cfg.drive.frequency_Hz)
            # loads: gravity + downforce on the FE body, distributed like its mass (as the FE tier)
            acceleration = gravity + force / model.total_mass_kg()
            self.fq = np.zeros(self.basis.size)
            for k in range(gdim):
                if acceleration[k]:
                    translation = ops.M.createVecRight()
                    _, sub = model.W.sub(0).sub(k).collapse()
                    sub = np.asarray(sub)
                    translation.array_w[sub[sub < translation.getLocalSize()]] = 1.0
                    load = ops.M.createVecLeft()
                    ops.M.mult(translation, load)
                    self.fq += acceleration[k] * self.basis.project_vector(load)
                    translation.destroy()
                    load.destroy()
            ops.destroy()
        self.reduction_wall_s = time.perf_counter() - start
        basis = self.basis
        log(f"modal tier: {basis.n_interface} interface DOFs, {len(electrodes)} electrode(s), {basis.n_modes} "
            f"fixed-interface modes up to {basis.mode_frequencies_Hz.max():.0f} Hz "
            + ("(loaded from the checkpoint)" if saved is not None else f"({self.reduction_wall_s:.2f} s)"))

        # rigid bodies
        nb = len(cfg.bodies)
        self.body_mass = np.array([b.mass_kg for b in cfg.bodies], dtype=float)
        self.z0 = np.concatenate([np.asarray(b.position_m, dtype=float) for b in cfg.bodies]) if nb else np.zeros(0)
        self.zd0 = np.concatenate([np.asarray(b.velocity_m_per_s or [0.0] * gdim, dtype=float)
                                   for b in cfg.bodies]) if nb else np.zeros(0)
        self.zfree = np.concatenate([np.array([False] * gdim) if b.fixed else np.asarray(b.free_axes or [True] * gdim)
                                     for b in cfg.bodies]).astype(np.bool_) if nb else np.zeros(0, np.bool_)
        self.body_force = np.concatenate([
            (b.mass_kg * gravity + np.asarray(b.applied_force_N or [0.0] * gdim, dtype=float)) for b in cfg.bodies
        ]) if nb else np.zeros(0)
        self.zd0[~self.zfree] = 0.0

        # contacts: node contacts first, then rigid-rigid links (the kernel's order)
        self.order = [c.name for c, _, _ in nodes] + [c.name for c in cfg.contacts if c.kind == "point"]
        nn = len(nodes)
        self.nc_coord = np.full((nn, gdim), -1, dtype=np.int64)
        self.nc_normal = np.zeros((nn, gdim))
        self.nc_offset = np.zeros(nn)
        self.nc_ref = np.zeros((nn, gdim))
        self.nc_body = np.zeros(nn, dtype=np.int64)
        self.nc_k = np.zeros(nn)
        self.nc_c = np.zeros(nn)
        self.nc_exp = np.full(nn, 1.5)
        for i, (c, x_node, coords) in enumerate(nodes):
            b = body_index[c.body]
            ref = self.z0[b * gdim:(b + 1) * gdim]
            n = np.asarray(c.normal, dtype=float)
            self.nc_coord[i] = coords
            self.nc_normal[i] = n
            self.nc_ref[i] = ref
            self.nc_offset[i] = n @ (x_node - ref) - c.radius_m
            self.nc_body[i] = b
            self.nc_k[i], self.nc_c[i] = c.stiffness, c.damping
        points = [c for c in cfg.contacts if c.kind == "point"]
        self.pc_lower = np.array([body_index[c.lower] for c in points], dtype=np.int64)
        self.pc_upper = np.array([body_index[c.upper] for c in points], dtype=np.int64)
        self.pc_dir = np.array([np.asarray(c.direction, float) / np.linalg.norm(c.direction) for c in points]
                               ).reshape(len(points), gdim)
        self.pc_touch = np.array([c.touch_distance_m for c in points], dtype=float)
        self.pc_k = np.array([c.stiffness for c in points], dtype=float)
        self.pc_c = np.array([c.damping for c in points], dtype=float)
        self.order += [c.name for c in cfg.contacts if c.kind == "surface"]
        self.surface = kernel_surface_arrays(surfaces, list(interface), gdim)

        # named points: their displacement component as a row on q
        self.sample_names = list(case.points)
        if saved is not None:
            self.sample_rows = saved.sample_rows
        else:
            self.sample_rows = np.zeros((len(self.sample_names), basis.size))
            for j, column in enumerate(basis.columns):
                values = model.point_values(column)
                for i, name in enumerate(self.sample_names):
                    self.sample_rows[i, j] = values[name]
        self.prescribed = np.array([basis.electrode_index(n) for n in electrodes], dtype=np.int64)
        self.electrode_names = list(electrodes)
        self.free = np.setdiff1d(np.arange(basis.size), self.prescribed).astype(np.int64)

    def _surface_contacts(self, interface: list[int], body_index: dict) -> list[SurfaceContactSpec]:
        """The case's surface contacts as node sets with lumped areas (app.reduced.surface); their
        nodes' displacement DOFs join the interface after the node contacts'."""
        from app.fe.model import facet_group_tag
        from forms.kinematics import volume_weight

        case, model, file, gdim = self.case, self.model, self.case.source, self.gdim
        weight = volume_weight(model.mesh, model.kind, case.geometry.thickness_m)
        specs = []
        for i, c in enumerate(self.cfg.contacts):
            if c.kind != "surface":
                continue
            key = f"transient.contacts[{i}]"
            if c.friction is not None:       # also refused when the case is read (app.case.schema)
                raise CaseError(file, f"{key}.friction", "friction is not available in tier 'modal' yet")
            tag = facet_group_tag(model.mesh_data.facet_names, c.facets, file, f"{key}.facets")
            normal = None if c.normal is None else np.asarray(c.normal, dtype=float)
            if normal is not None and (normal.size != gdim or not math.isclose(np.linalg.norm(normal), 1.0,
                                                                               rel_tol=1e-9)):
                raise CaseError(file, f"{key}.normal", f"must be a unit vector with {gdim} components")
            nodes = surface_nodes(model.W, model.W.sub(0), model.mesh_data.facet_tags, tag, weight,
                                  model.support_dofs)
            if nodes.size == 0:
                raise CaseError(file, f"{key}.facets", f"facet group {c.facets!r} has no nodes")
            b = body_index[c.body]
            start_m = np.asarray(self.cfg.bodies[b].position_m, dtype=float)     # the obstacle's reference
            specs.append(SurfaceContactSpec(nodes, b, start_m, c.shape, normal, c.radius_m or 0.0, c.stiffness,
                                            c.damping))
            for row in nodes.global_dofs:
                interface += [int(d) for d in row if d >= 0 and int(d) not in interface]
        return specs

    # --------------------------------------------------------------- initial state
    def drive(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(voltage scale V, per-electrode amplitudes [V], phases [rad]) of the drive."""
        cfg, case = self.cfg, self.case
        amplitudes = np.array([case.electrodes[n].amplitude_V if case.electrodes[n].amplitude_V is not None
                               else 1.0 for n in self.electrode_names])
        uses_scale = np.array([case.electrodes[n].amplitude_V is None for n in self.electrode_names])
        phases = np.radians([case.electrodes[n].phase_deg for n in self.electrode_names])
        scale = cfg.drive.voltage_V
        if cfg.drive.tip_amplitude_m is not None:
            per_scale = abs(self.sample_rows[self.sample_names.index(self.drive_point)]
                            @ self._phasor(amplitudes, phases))
            if not per_scale > 0:
                raise NumericalFailure("the drive does not move the drive point (reduced harmonic solve)")
            scale = cfg.drive.tip_amplitude_m / per_scale
            amplitudes = amplitudes * scale                 # a target amplitude scales every electrode
        else:
            amplitudes = np.where(uses_scale, amplitudes * scale, amplitudes)
        return scale, amplitudes, phases

    def _phasor(self, amplitudes: np.ndarray, phases: np.ndarray) -> np.ndarray:
        voltages = {n: a * np.exp(1j * p) for n, a, p in zip(self.electrode_names, amplitudes, phases)}
        return harmonic_response(self.basis, self.cfg.drive.frequency_Hz, voltages, self.fq * 0.0)

    def initial_state(self, amplitudes: np.ndarray, phases: np.ndarray):
        """(q, v, a, z, zd, zdd) at t = 0: rest (the free coordinates cancel the moving electrode
        modes' velocity, see app.reduced.integrator) or the reduced harmonic steady state."""
        basis, cfg = self.basis, self.cfg
        omega = 2 * math.pi * cfg.drive.frequency_Hz
        q, v, a = np.zeros(basis.size), np.zeros(basis.size), np.zeros(basis.size)
        P, F = self.prescribed, self.free
        if cfg.initial_state == "harmonic":
            x = self._phasor(amplitudes, phases)            # U = A cos(wt + phase)
            q, v, a = x.real.copy(), -omega * x.imag, -omega**2 * x.real
        else:                                               # U = A sin(wt + phase)
            q[P] = amplitudes * np.sin(phases)
            v[P] = amplitudes * omega * np.cos(phases)
            a[P] = -amplitudes * omega**2 * np.sin(phases)
            MFF = basis.M[np.ix_(F, F)]
            q[F] = -np.linalg.solve(MFF, basis.M[np.ix_(F, P)] @ q[P])
            v[F] = -np.linalg.solve(MFF, basis.M[np.ix_(F, P)] @ v[P])
        # accelerations of the free coordinates from the equations of motion (gravity included)
        rhs = self.fq - basis.K @ q - (basis.C @ v if basis.C is not None else 0.0) - basis.M[:, P] @ a[P]
        a[F] = np.linalg.solve(basis.M[np.ix_(F, F)], rhs[F])
        z, zd = self.z0.copy(), self.zd0.copy()
        zdd = np.zeros_like(z)
        for b, mass in enumerate(self.body_mass):
            if mass > 0:
                sl = slice(b * self.gdim, (b + 1) * self.gdim)
                zdd[sl] = self.body_force[sl] / mass
        zdd[~self.zfree] = 0.0
        return q, v, a, z, zd, zdd


def _node_dofs(model, point: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """(node coordinates, global displacement DOF per axis or -1 if held) of the mesh node nearest
    ``point`` (the same node on every rank)."""
    comm = model.comm
    W = model.W
    imap = W.dofmap.index_map
    n_owned = imap.size_local
    held = set(np.asarray(model.support_dofs).tolist())
    out, x_node = [], None
    for k in range(model.mesh.geometry.dim):
        V, parent = W.sub(0).sub(k).collapse()
        parent = np.asarray(parent)
        coords = V.tabulate_dof_coordinates()[:, : point.size]
        owned = parent < n_owned
        dist = np.linalg.norm(coords - point[: coords.shape[1]], axis=1)
        dist[~owned] = np.inf
        best = int(np.argmin(dist)) if dist.size else -1
        d = float(dist[best]) if best >= 0 else np.inf
        _, owner = comm.allreduce((d, comm.rank), op=MPI.MINLOC)
        if comm.rank == owner:
            local = int(parent[best])
            dof = -1 if local in held else int(imap.local_to_global(np.array([local], dtype=np.int32))[0])
            x = coords[best]
        else:
            dof, x = None, None
        out.append(comm.bcast(dof, root=owner))
        x_node = comm.bcast(x, root=owner)
    return np.asarray(x_node, dtype=float), out


def run(case, out_dir, comm, log, resume: bool = False) -> dict:
    """Run the transient analysis of ``case`` in the modal tier into ``out_dir``; with ``resume``
    continue from the checkpoint in ``out_dir`` (same case except the end time, the checkpoint
    interval and the outputs) and append to its time series and field series.

    The compiled loop runs in calls that end when its row buffer is full, at a checkpoint (every
    ``transient.checkpoint_interval_steps`` accepted steps: the buffer holds just the steps up to
    it) or after the step that reaches a field output time; between calls the driver writes the
    rows, expands the fields (x = T q, only then) and writes the checkpoint. No Python per step."""
    from app.blas import limit_blas_threads
    from app.transient.impacts import statistics_from_file

    limit_blas_threads()    # the kernel's small products: threads cost more than they give (BENCHMARKS.md)
    cfg = case.transient
    out_dir = Path(out_dir)
    setup_start = time.perf_counter()
    digest = case_digest(case)
    found = read_checkpoint(out_dir, comm, case, digest, needs=(restart.MODEL_KEY,)) if resume else None
    restore = (lambda model, layout: restart.load_model(out_dir, model, layout)) if found is not None else None
    scene = ReducedScene(case, comm, log, restore=restore)
    gdim = scene.gdim
    n_contacts = len(scene.order)
    if found is not None:
        meta, data = found
        saved = scene.saved
        scale, amplitudes, phases = saved.drive_scale_V, saved.amplitudes_V, saved.phases_rad
        q, v, a, z, zd, zdd, istate, fstate = (np.array(data[k]) for k in restart.STATE_ARRAYS)
        resumed_rows, seq = int(meta["rows"]), int(meta["seq"])
        log(f"transient (modal tier): resuming at t = {fstate[kr.F_TIME] * 1e3:.6g} ms from {out_dir / 'checkpoint'} "
            f"({resumed_rows} time-series rows kept)")
    else:
        if resume:
            log(f"transient (modal tier): {out_dir} holds a run killed before its first checkpoint: starting it again")
        mark_started(out_dir, comm, digest)
        scale, amplitudes, phases = scene.drive()
        q, v, a, z, zd, zdd = scene.initial_state(amplitudes, phases)
        if cfg.initial_state == "harmonic":
            kill_point("harmonic_start")
        restart.save_model(out_dir, scene, scene.layout, scale, amplitudes, phases)
        istate = np.zeros(kr.N_ISTATE, np.int64)
        fstate = np.zeros(kr.N_FSTATE)
        fstate[kr.F_CAP] = np.inf
        resumed_rows, seq = None, 0
    t_start = float(fstate[kr.F_TIME])
    fstate[kr.F_OUTPUT] = np.inf
    closed = np.zeros(n_contacts, np.bool_)
    cap = ROWS_PER_CHUNK
    buffers = [np.zeros(cap), np.zeros(cap), np.zeros((cap, len(scene.sample_names))),
               np.zeros((cap, scene.prescribed.size)), np.zeros((cap, z.size)), np.zeros((cap, z.size)),
               np.zeros((cap, n_contacts)), np.zeros((cap, n_contacts), np.bool_),
               np.zeros((cap, scene.surface["sc_k"].size * gdim))]
    units = {S.TIME: "s", S.STEP: "s", S.DRIVE: "V"}
    units.update({S.point_displacement(n): "m" for n in scene.sample_names})
    for name in scene.names["bodies"]:
        units.update(S.body_columns(name))
    for name in scene.order:
        units.update(S.contact_columns(name))
    h5_path = out_dir / S.TIME_SERIES_FILE
    series = TimeSeriesWriter(h5_path, units, comm, resume_rows=resumed_rows)
    checkpoint = CheckpointWriter(out_dir, scene.layout, cfg.checkpoint_interval_steps, scale, digest, seq=seq)
    basis = scene.basis
    fields = None
    if case.output.fields:
        expanded = basis.columns[0].duplicate()

        def solution():
            basis.expand(q, expanded)           # x = T q, at the output interval only
            return expanded

        bodies = [(name, slice(b * gdim, (b + 1) * gdim), cfg.bodies[b].position_m)
                  for b, name in enumerate(scene.names["bodies"])]
        fields = FieldSeriesExport(out_dir / "transient_fields.xdmf", scene.model, solution, cfg.output_interval_s,
                                   bodies=bodies, resume_from_s=t_start if found is not None else None)
        if found is None:
            fields.write(0.0, z)
    s = cfg.scheme.scheme()
    st = cfg.steps
    omega = 2 * math.pi * cfg.drive.frequency_Hz
    cosine = cfg.initial_state == "harmonic"
    # the kernel's drive is A sin(wt + phase) or A cos(wt + phase)
    directions = _force_directions(scene)
    log(f"transient (modal tier): {cfg.initial_state} start, drive {scale:.4g} V at {cfg.drive.frequency_Hz:.2f} Hz, "
        f"{len(scene.names['bodies'])} rigid bodies, {n_contacts} contacts, {cfg.end_time_s * 1e3:.4g} ms")
    # an undamped model (no Rayleigh, no material Q) has no C: the kernel takes zeros
    damping = basis.C if basis.C is not None else np.zeros_like(basis.K)
    # K_eff^-1 per step size, kept across the loop's calls (a function of dt only, see the kernel)
    cache_dt = np.full(kr.CACHE_SLOTS, -1.0)
    cache_inv = np.zeros((kr.CACHE_SLOTS, scene.free.size, scene.free.size))

    def arguments(t_end, rows):
        return (t_end, q, v, a, z, zd, zdd, closed, istate, fstate,
                basis.K, basis.M, damping, scene.fq, scene.free, scene.prescribed,
                amplitudes, phases, omega, cosine, scene.body_mass, scene.body_force, scene.zfree,
                gdim, scene.nc_coord, scene.nc_normal, scene.nc_offset, scene.nc_ref, scene.nc_body,
                scene.nc_k, scene.nc_c, scene.nc_exp, scene.pc_lower, scene.pc_upper, scene.pc_dir,
                scene.pc_touch, scene.pc_k, scene.pc_c, *[scene.surface[k] for k in SURFACE_KEYS],
                s.beta, s.gamma, s.alpha_m, s.alpha_f,
                st.open_s, st.closed_s, st.change_s, st.min_s, 2.0, scene.sample_rows,
                *(buffer[:rows] for buffer in buffers), cache_dt, cache_inv)

    kr.run(*arguments(0.0, cap))    # loads (or compiles) the kernel: set-up, not time-loop cost
    setup_wall = time.perf_counter() - setup_start
    interval = int(cfg.checkpoint_interval_steps)
    checkpointed_at = int(istate[kr.I_STEPS]) if found is not None else -1
    field_wall = checkpoint_wall = 0.0
    start = time.perf_counter()
    try:
        while True:
            steps = int(istate[kr.I_STEPS])
            rows_wanted = cap if interval <= 0 else min(cap, interval - steps % interval)
            if fields is not None:      # the kernel stops after the first step at or after this time
                fstate[kr.F_OUTPUT] = fields.next_s - FIELD_TIME_TOLERANCE * fields.interval_s
            code, rows = kr.run(*arguments(cfg.end_time_s, rows_wanted))
            if rows:
                block = {S.TIME: buffers[0][:rows], S.STEP: buffers[1][:rows],
                         S.DRIVE: buffers[3][:rows, 0] if scene.prescribed.size else np.zeros(rows)}
                for i, name in enumerate(scene.sample_names):
                    block[S.point_displacement(name)] = buffers[2][:rows, i]
                for b, name in enumerate(scene.names["bodies"]):
                    block[S.body_position(name)] = buffers[4][:rows, b * gdim:(b + 1) * gdim]
                    block[S.body_velocity(name)] = buffers[5][:rows, b * gdim:(b + 1) * gdim]
                n_scalar = len(directions)
                for i, name in enumerate(scene.order):
                    if i < n_scalar:
                        block[S.contact_force(name)] = buffers[6][:rows, i:i + 1] * directions[i][None, :]
                    else:                       # a surface contact: its force vector on the body
                        c = i - n_scalar
                        block[S.contact_force(name)] = buffers[8][:rows, c * gdim:(c + 1) * gdim]
                    block[S.contact_closed(name)] = buffers[7][:rows, i].astype(float)
                series.write_block(block)
                kill_point("series_block")
            if code == kr.STEP_FAILED:
                raise NumericalFailure(f"modal tier: step failed at t = {fstate[kr.F_TIME]:.6e} s after "
                                       f"{istate[kr.I_CUTBACKS]} cut-backs (dt below min_s = {st.min_s:.3e} s)")
            if fields is not None and code == kr.FIELD_OUTPUT:
                mark = time.perf_counter()
                fields.write(float(fstate[kr.F_TIME]), z)
                field_wall += time.perf_counter() - mark
            steps = int(istate[kr.I_STEPS])
            if (code == kr.DONE or checkpoint.due(steps)) and steps != checkpointed_at:
                mark = time.perf_counter()
                state = {"q": q, "v": v, "a": a, "z": z, "zd": zd, "zdd": zdd, "istate": istate, "fstate": fstate}
                counters = {"steps": steps, "attempts": int(istate[kr.I_ATTEMPTS]),
                            "cutbacks": int(istate[kr.I_CUTBACKS])}
                checkpoint.write_arrays(float(fstate[kr.F_TIME]), state, counters,
                                        rows_of=lambda: series.rows_written,
                                        meta={restart.MODEL_KEY: restart.MODEL_FILE})
                checkpointed_at = steps
                checkpoint_wall += time.perf_counter() - mark
            if code == kr.DONE:
                break
    finally:
        series.close()
        if fields is not None:
            fields.close()
    wall = time.perf_counter() - start
    simulated = cfg.end_time_s - t_start
    results = {"tier": "modal", "steps": int(istate[kr.I_STEPS]), "attempts": int(istate[kr.I_ATTEMPTS]),
               "cutbacks": int(istate[kr.I_CUTBACKS]), "event_refinements": int(istate[kr.I_REFINEMENTS]),
               "newton_iterations": int(istate[kr.I_NEWTON]), "wall_time_s": wall, "setup_wall_s": setup_wall,
               "field_output_wall_s": field_wall, "checkpoint_wall_s": checkpoint_wall,
               "reduction_wall_s": scene.reduction_wall_s,
               "wall_s_per_simulated_ms": wall / (simulated * 1e3) if simulated > 0 else None,
               "simulated_time_s": cfg.end_time_s, "resumed_from_s": t_start if found is not None else None,
               "drive_voltage_V": scale, "drive_frequency_Hz": cfg.drive.frequency_Hz,
               "initial_state": cfg.initial_state, "time_series": h5_path.name,
               "checkpoint": f"{checkpoint.dir.name}/{POINTER}", "checkpoints_written": checkpoint.written,
               "fields": fields.path.name if fields is not None else None,
               "field_outputs": fields.written if fields is not None else 0,
               "reduction": {"interface_dofs": basis.n_interface, "electrodes": scene.electrode_names,
                             "modes": basis.n_modes, "size": basis.size,
                             "highest_mode_Hz": float(basis.mode_frequencies_Hz.max()),
                             "cutoff_Hz": scene.cutoff_Hz, "from_checkpoint": found is not None}}
    log(f"transient (modal tier): {results['steps']} steps, {results['newton_iterations']} Newton iterations, "
        f"{results['cutbacks']} cut-backs, {wall:.2f} s wall"
        + (f" ({results['wall_s_per_simulated_ms']:.4f} s per simulated ms)" if simulated > 0 else "")
        + f"; of it {checkpoint.written} checkpoints {checkpoint_wall:.2f} s, {fields.written if fields else 0} "
          f"field outputs {field_wall:.2f} s")
    summaries = statistics_from_file(h5_path, case) if comm.rank == 0 else None
    results["contacts"], results["statistics"] = comm.bcast(summaries, root=0)
    results["outputs"] = [h5_path.name, *checkpoint.files(), *restart.checkpoint_files(out_dir),
                          *(fields.files() if fields is not None else [])]
    bodies = [name for b, name in enumerate(scene.names["bodies"]) if scene.zfree[b * gdim:(b + 1) * gdim].any()]
    results["scene"] = case.scene
    results["plot"] = plot_spec(case, scene.drive_point, bodies, scene.order, tier=" (modal tier)")
    if case.output.plots and comm.rank == 0:      # the FE tier's plots, from the same series
        from app.plots import time_series_outputs

        results["plots"] = time_series_outputs(out_dir, results)
        results["outputs"] += results["plots"]
    if fields is not None:
        expanded.destroy()
    basis.destroy()
    return results


def _force_directions(scene: ReducedScene) -> list[np.ndarray]:
    """Unit vector of each contact's reported force (the FE tier's convention: on the rigid body for
    a node contact, on the upper body for a rigid-rigid link)."""
    out = [-scene.nc_normal[i] for i in range(scene.nc_k.size)]
    out += [scene.pc_dir[i] for i in range(scene.pc_k.size)]
    return out
