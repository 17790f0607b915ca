"""The FE tier's engine for the run loop (app/loop/loop.py): the transient model of a case
(app/transient/driver.py: FE part, rigid bodies, interactions), stepped by :class:`TimeStepper`, its rows
under the output convention of every tier (app/series.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from app import series as S
from app.errors import CaseError
from app.fe.layout import CellLayout
from app.killpoint import kill_point
from app.loop.checkpoint import Found
from app.transient.control import StepController, StepSizes
from app.transient.driver import PointSampler, TransientModel, build, units
from app.transient.impacts import statistics_from_file
from app.transient.state import TransientState
from app.transient.stepper import TimeStepper

#: the most rows one advance() collects before handing them to the loop (a block of the series file)
BLOCK_ROWS = 2000


class FEEngine:
    """The FE tier as an :class:`app.loop.loop.Engine`."""

    tier = "fe"

    def __init__(self, case, comm, log, found: Found | None = None):
        self.comm, self.log = comm, log
        self.tm: TransientModel = build(case, comm, log)
        # the case as run: a drive locked to the resonance has its frequency resolved (app/drive.py locked_case)
        self.case = case = self.tm.case
        self.cfg = cfg = case.transient
        self.system = self.tm.system
        self.layout = CellLayout(self.tm.model.W)
        s = cfg.steps
        sizes = StepSizes(open_s=s.open_s, closed_s=s.closed_s, change_s=s.change_s, min_s=s.min_s)
        self.stepper = TimeStepper(self.system, StepController(sizes), track_energy=case.output.energies)
        self.sampler = PointSampler(self.tm.model)
        self.charges = self._charge_vectors() if case.output.energies else {}
        self.sites = SiteProbe(case, self.tm) if case.output.contact_sites else None
        self.pressures = self._pressure_probes() if case.output.contact_pressure else []
        self._pressures_of = None          # the state the pressure fields were last evaluated at
        self.end_time_s = cfg.end_time_s
        self.checkpoint_interval_steps = cfg.checkpoint_interval_steps
        self.state: TransientState | None = None
        self.voltage_V = 0.0

    @classmethod
    def check(cls, case, comm, log) -> None:
        """``validate``: every check the run makes that needs the mesh, without solving (collective)."""
        from app.loop.loop import steady_state_watch

        tm = build(case, comm, log, lock_drive=False)
        try:
            steady_state_watch(case, units(tm, case))
        finally:
            tm.system.destroy()

    # ---------------------------------------------------------------- start / restore
    def start(self) -> None:
        self.state, self.voltage_V = self.tm.initial_state()
        if self.sites is not None:
            self.sites.tables.geometry(self.sites.points, self.sites.record.weight)
        self._started()

    def restore(self, found: Found) -> None:
        data = found.arrays
        try:
            u, v, a = (self.layout.scatter(data[k]) for k in ("u", "v", "a"))
        except ValueError as exc:
            from app.errors import CaseError

            raise CaseError(str(found.pointer), "mesh", str(exc)) from None
        self.state = TransientState(found.t_s, u, v, a, data["z"], data["zd"], data["zdd"])
        self.voltage_V = float(found.engine["voltage_V"])
        self.tm.resume_drive(self.voltage_V)
        self.stepper.restore(found.engine["stepper"])
        if self.sites is not None:
            self.sites.tables.restore(data, found.engine)
        self._started()

    def _charge_vectors(self) -> dict:
        """Per driven electrode the vector w = K 1_e: its charge Q_e = -w . x [C] (the reaction of its potential
        DOFs, as the modal tier's charge rows; K symmetric, assembled without boundary conditions)."""
        model, fe = self.tm.model, self.tm.fe
        out = {}
        for name in model.electrodes_of("voltage"):
            ones = fe.new_vector()
            dofs = np.asarray(model.electrode_dofs[name])
            ones.array_w[dofs[dofs < fe.n_owned]] = 1.0
            w = fe.new_vector()
            fe.K.mult(ones, w)
            out[name] = w
            ones.destroy()
        return out

    def _pressure_probes(self) -> list:
        """``output.contact_pressure``: a :class:`app.transient.contact.ContactPressureProbe` per surface contact."""
        from app.transient.contact import ContactPressureProbe, SurfaceContact

        return [ContactPressureProbe(c) for c in self.system.interactions if isinstance(c, SurfaceContact)]

    def _evaluate_pressures(self) -> None:
        """Every surface contact's pressure field at the current (end-of-step) state, once per state: a field
        frame taken at the step whose row already evaluated them reuses them (one facet assembly per step)."""
        state, rigid = self.state, self.tm.rigid
        if self._pressures_of == (id(state), state.t):
            return
        self._pressures_of = (id(state), state.t)
        for probe in self.pressures:
            body = probe.contact.body
            sl = rigid.dofs(body)
            omega = rigid.angular_velocity(body, state.zd) if probe.body_angular_velocity is not None else None
            probe.evaluate(state, state.z[sl], state.zd[sl], omega)

    def _pressure_fields(self, vertex) -> dict:
        """The field file's ``contact_pressure_Pa``: the sum of the surface contacts' pressures (their facet
        groups do not overlap), at the vertices on rank 0."""
        self._evaluate_pressures()
        total = None
        for probe in self.pressures:
            values = vertex.sample_scalar(probe.pressure)
            if values is not None:
                total = values if total is None else total + values
        from app.transient.fields import CONTACT_PRESSURE

        return {CONTACT_PRESSURE: (total, "Pa")}

    def _started(self) -> None:
        cfg = self.cfg
        self.log(f"transient: {cfg.initial_state} start, drive {self.voltage_V:.4g} V at {cfg.drive.frequency_Hz:.2f} "
                 f"Hz, {len(self.tm.rigid.bodies)} rigid bodies, {len(cfg.contacts)} contacts, "
                 f"{cfg.end_time_s * 1e3:.4g} ms")
        self.stepper.begin(self.state)

    @property
    def t(self) -> float:
        return self.state.t

    @property
    def steps(self) -> int:
        return self.stepper.stats.steps

    # ---------------------------------------------------------------- stepping
    def columns(self) -> dict[str, str]:
        out = units(self.tm, self.case)
        if self.charges:
            out.update({S.electrode_charge(name): "C" for name in self.charges})
            out.update(S.ENERGY_COLUMNS)
        if self.sites is not None:
            out.update(self.sites.columns())
        out.update({S.contact_peak_pressure(p.contact.name): "Pa" for p in self.pressures})
        return out

    def advance(self, t_end: float, max_steps: int, stop_at_s: float) -> dict[str, np.ndarray]:
        rows = []
        taken = 0
        while self.state.t < t_end * (1 - 1e-12) and taken < max_steps and len(rows) < BLOCK_ROWS:
            self.state, rec = self.stepper.step(self.state, t_end)
            rows.append(self._row(rec))
            taken += 1
            if self.sites is not None and self.sites.tables.due(self.state.t):
                self.sites.tables.row(self.state.t)
            kill_point("step")
            if self.state.t >= stop_at_s:
                break
        if not rows:
            return {}
        return {name: np.array([r[name] for r in rows], dtype=float) for name in rows[0]}

    def _row(self, rec: dict) -> dict:
        tm, system = self.tm, self.system
        t = rec["time_s"]
        row = {S.TIME: t, S.STEP: rec["dt_s"], S.DRIVE: tm.drive.voltage_V(t)}
        if len(tm.drive.electrodes) > 1:
            for name, value in tm.drive.electrode_voltages_V(t).items():
                row[S.electrode_voltage(name)] = value
        for name, value in self.sampler.values(system.solution_array).items():
            row[S.point_displacement(name)] = value
        for b in tm.rigid.bodies:
            sl = tm.rigid.dofs(b.name)
            row[S.body_position(b.name)] = rec["position_m"][sl]
            row[S.body_velocity(b.name)] = rec["velocity_m_per_s"][sl]
            if b.rotation_axes:
                rot = tm.rigid.rotation_dofs(b.name)
                row[S.body_angle(b.name)] = rec["position_m"][rot]
                row[S.body_angular_velocity(b.name)] = rec["velocity_m_per_s"][rot]
        for j, c in enumerate(system.interactions):
            row.update(c.row(rec["contact_force_N"][c.name], bool(rec["contact_closed"][j])))
            row[S.contact_dissipated(c.name)] = rec["dissipated_J"][c.name]
        if self.charges:
            x = system.solution_vector
            for name, w in self.charges.items():
                row[S.electrode_charge(name)] = -w.dot(x)
            energy = rec["energy_J"]
            row["kinetic_energy_J"] = energy["kinetic_fe_J"]
            row["strain_energy_J"] = energy["strain_fe_J"]
            row["rigid_kinetic_energy_J"] = energy["kinetic_rigid_J"]
            row["contact_energy_J"] = energy["contact_J"]
            row["damping_dissipated_J"] = rec["damping_dissipated_J"]
        if self.sites is not None:
            row.update(self.sites.step(self.state, rec["dt_s"]))
        if self.pressures:
            self._evaluate_pressures()
            for probe in self.pressures:
                row[S.contact_peak_pressure(probe.contact.name)] = probe.peak_Pa()
        return row

    def take_tables(self) -> dict:
        return self.sites.tables.take() if self.sites is not None else {}

    # ---------------------------------------------------------------- checkpoints, fields, results
    def snapshot(self) -> tuple[dict | None, dict]:
        state = self.state
        fields = {k: self.layout.gather(getattr(state, k)) for k in ("u", "v", "a")}
        record = {"voltage_V": self.voltage_V, "stepper": self.stepper.snapshot()}
        site_arrays = {}
        if self.sites is not None:
            site_arrays, site_record = self.sites.tables.snapshot()
            record.update(site_record)
        arrays = dict(z=state.z, zd=state.zd, zdd=state.zdd, **fields, **site_arrays) if self.comm.rank == 0 else None
        return arrays, record

    def checkpoint_files(self, out_dir: Path) -> dict[str, str]:
        return {}

    def field_export(self, out_dir: Path, resume_from_s: float | None):
        if not self.case.output.fields:
            return None
        from app.exports import VertexFields
        from app.transient.body_shapes import BodyMeshes
        from app.transient.fields import FieldSeriesExport, frame_schedule

        tm, system, case = self.tm, self.system, self.case
        slices = {b.name: tm.rigid.all_dofs(b.name) for b in tm.rigid.bodies}
        vertex = VertexFields(tm.model, self.case.output.derived)
        scalars = (lambda: self._pressure_fields(vertex)) if self.pressures else None
        export = FieldSeriesExport(Path(out_dir) / "transient_fields.xdmf", vertex,
                                   lambda: system.solution_vector, frame_schedule(self.case),
                                   bodies=lambda size: BodyMeshes(case.transient, case.geometry.model, slices, size),
                                   resume_from_s=resume_from_s, scalars=scalars)
        if resume_from_s is None:
            system.show_state(self.state)
        return export

    def body_positions(self) -> np.ndarray:
        return self.state.z

    def results(self) -> dict:
        self.stepper._finish_statistics()
        out = dict(self.stepper.stats.as_dict())
        out.pop("steps", None)
        out.pop("wall_time_s", None)
        cfg = self.cfg
        out.update({"drive_voltage_V": self.voltage_V, "drive_frequency_Hz": cfg.drive.frequency_Hz,
                    "initial_state": cfg.initial_state, "stepping_wall_time_s": self.stepper.stats.wall_time_s})
        if self.tm.drive_lock is not None:
            out["drive"] = self.tm.drive_lock
        self.log(f"transient: {self.steps} steps, {out['newton_iterations']} Newton iterations, "
                 f"{out['cutbacks']} cut-backs, {out['factorisations']} factorisations")
        return out

    def statistics(self, h5_path: Path) -> tuple[dict, dict]:
        return statistics_from_file(h5_path, self.case)

    def close(self) -> None:
        self.system.destroy()


class SiteProbe:
    """The FE tier's per-site diagnostics (``output.contact_sites``): the sites of every sampled surface contact
    (app/contact/sites.py, the modal tier's sampling) evaluated after every step from the FE fields, with the
    contact law at a point (app/contact/law.py), into the tables of app/contact/tables.py; and each contact's
    first site's displacement in its frame (the contact point's path, ``<contact>_probe_displacement_m``)."""

    def __init__(self, case, tm):
        from dolfinx import fem

        from app.contact.law import site_work
        from app.contact.records import bodies_record, contact_records, sites_record
        from app.contact.sites import contact_site_sets
        from app.contact.tables import SiteTables, site_groups
        from app.fe.probe import PointSet

        model = tm.model
        self.gdim = gdim = model.mesh.geometry.dim
        sets, _, _ = contact_site_sets(case, model)
        surface = [s for s in sets if case.transient.contacts[s.contact].kind == "surface"]
        self.points = np.concatenate([s.points_m for s in surface]) if surface else np.zeros((0, 3))
        weight = np.concatenate([s.weight for s in surface]) if surface else np.zeros(0)
        index = np.concatenate([np.full(s.points_m.shape[0], s.contact) for s in surface]).astype(np.int64) \
            if surface else np.zeros(0, np.int64)
        gravity = np.asarray(case.transient.loads.gravity_m_per_s2 or [0.0] * gdim, dtype=float)
        self.bodies, self.slices = bodies_record(case, gdim, gravity)
        self.contacts, _ = contact_records(case)
        self.record = sites_record(case, self.points, weight, index, np.zeros((self.points.shape[0] * gdim, 0)),
                                   self.contacts, self.bodies)
        self.pointset = PointSet(model.mesh, self.points[:, :gdim])
        if self.pointset.missing.size:
            raise CaseError(case.source, "transient.contacts", f"{self.pointset.missing.size} contact sample points "
                                                               "lie outside the mesh")
        V, parent = model.W.sub(0).collapse()          # the displacement space: eval takes no mixed element
        self.parent = np.asarray(parent)
        self.u = fem.Function(V)
        self.v = fem.Function(V)
        names = [c.name for c in case.transient.contacts]
        self.tables = SiteTables([(s.name, index == s.contact) for s in surface], self.points.shape[0],
                                 case.transient.output_interval_s, site_groups(case, index))
        self.omega = 2 * math.pi * case.transient.drive.frequency_Hz      # the case as run: a locked drive resolved
        self.first = {s.name: int(np.argmax(index == s.contact)) for s in surface}
        self.work = site_work(self.bodies.mass.size)
        self.rigid = tm.rigid
        self.names = names

    def columns(self) -> dict[str, str]:
        return {S.contact_probe(name): "m (n, e1, e2)" for name in self.first}

    def step(self, state, dt: float) -> dict:
        """Accumulate the step's site states (end-of-step fields) and return the probe columns of the row."""
        from app.contact.law import SiteAccumulators, accumulate_sites

        gdim = self.gdim
        self.u.x.array[:] = state.u[self.parent]
        self.v.x.array[:] = state.v[self.parent]
        y = np.zeros((self.points.shape[0], 3))
        v = np.zeros_like(y)
        y[:, :gdim] = self.pointset(self.u)[:, :gdim]
        v[:, :gdim] = self.pointset(self.v)[:, :gdim]
        z, zd = self._packed(state.z), self._packed(state.zd)
        tables = self.tables
        accumulate_sites(y, v, z, zd, dt, state.t, self.omega, self.record, self.contacts, self.bodies,
                         SiteAccumulators(tables.sums, tables.bins, tables.groups, tables.phase), self.work)
        return {S.contact_probe(name): self.record.frame[i] @ y[i] for name, i in self.first.items()}

    def _packed(self, values: np.ndarray) -> np.ndarray:
        """The FE tier's rigid coordinates in the law's body-major packing (the same: translations, then
        angles, body by body)."""
        return np.asarray(values, dtype=float)
