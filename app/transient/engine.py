"""The FE tier's engine for the run loop (app/loop/loop.py): the transient model of a case
(app/transient/driver.py: FE part, rigid bodies, interactions), stepped by :class:`TimeStepper`, its rows
under the output convention of every tier (app/series.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app import series as S
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
        self.case, self.comm, self.log = case, comm, log
        self.cfg = cfg = case.transient
        self.tm: TransientModel = build(case, comm, log)
        self.system = self.tm.system
        self.layout = CellLayout(self.tm.model.W)
        s = cfg.steps
        sizes = StepSizes(open_s=s.open_s, closed_s=s.closed_s, change_s=s.change_s, min_s=s.min_s)
        self.stepper = TimeStepper(self.system, StepController(sizes))
        self.sampler = PointSampler(self.tm.model)
        self.end_time_s = cfg.end_time_s
        self.checkpoint_interval_steps = cfg.checkpoint_interval_steps
        self.state: TransientState | None = None
        self.voltage_V = 0.0

    @classmethod
    def check(cls, case, comm, log) -> None:
        """``validate``: every check the run makes that needs the mesh, without solving (collective)."""
        from app.loop.loop import steady_state_watch

        tm = build(case, comm, log)
        try:
            steady_state_watch(case, units(tm, case))
        finally:
            tm.system.destroy()

    # ---------------------------------------------------------------- start / restore
    def start(self) -> None:
        self.state, self.voltage_V = self.tm.initial_state()
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
        self._started()

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
        return units(self.tm, self.case)

    def advance(self, t_end: float, max_steps: int, stop_at_s: float) -> dict[str, np.ndarray]:
        rows = []
        taken = 0
        while self.state.t < t_end * (1 - 1e-12) and taken < max_steps and len(rows) < BLOCK_ROWS:
            self.state, rec = self.stepper.step(self.state, t_end)
            rows.append(self._row(rec))
            taken += 1
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
        return row

    def take_tables(self) -> dict:
        return {}

    # ---------------------------------------------------------------- checkpoints, fields, results
    def snapshot(self) -> tuple[dict | None, dict]:
        state = self.state
        fields = {k: self.layout.gather(getattr(state, k)) for k in ("u", "v", "a")}
        arrays = dict(z=state.z, zd=state.zd, zdd=state.zdd, **fields) if self.comm.rank == 0 else None
        return arrays, {"voltage_V": self.voltage_V, "stepper": self.stepper.snapshot()}

    def checkpoint_files(self, out_dir: Path) -> dict[str, str]:
        return {}

    def field_export(self, out_dir: Path, resume_from_s: float | None):
        if not self.case.output.fields:
            return None
        from app.exports import VertexFields
        from app.transient.fields import FieldSeriesExport

        tm, system = self.tm, self.system
        bodies = [(b.name, tm.rigid.dofs(b.name), b.position_m) for b in tm.rigid.bodies]
        export = FieldSeriesExport(Path(out_dir) / "transient_fields.xdmf", VertexFields(tm.model),
                                   lambda: system.solution_vector,
                                   self.cfg.output_interval_s, bodies=bodies, resume_from_s=resume_from_s)
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
        self.log(f"transient: {self.steps} steps, {out['newton_iterations']} Newton iterations, "
                 f"{out['cutbacks']} cut-backs, {out['factorisations']} factorisations")
        return out

    def statistics(self, h5_path: Path) -> tuple[dict, dict]:
        return statistics_from_file(h5_path, self.case)

    def close(self) -> None:
        self.system.destroy()
