"""Runner entry point of the ``transient`` analysis: case -> FE model + rigid bodies + contacts ->
time loop -> HDF5 time series, plots and a results dict for summary.json.

Loads on the FE body: gravity and a constant total force (the downforce) are applied as
mass-proportional body forces, i.e. the load vector of each axis k is M t_k (t_k the unit
translation) times (g_k + F_k / m_total). The drive voltage U(t) is prescribed on the potential DOFs
of electrodes of kind 'voltage', each with its own amplitude and phase (multi-phase drive:
U_e(t) = A_e sin(wt + phase_e) from rest, A_e cos(wt + phase_e) from the harmonic steady state);
supports, ground electrodes and non-piezoelectric regions are held at 0.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem

from app import series as S
from app.compat import petsc_vector
from app.drive import drive_weights, target_voltage
from app.errors import CaseError
from app.killpoint import kill_point
from app.transient.contact import MidpointFields
from app.transient.coupled import CoupledSystem
from app.transient.fe import LinearFE
from app.transient.interactions import BuildContext, build_interactions
from app.transient.motions import DirichletData, build_motions
from app.transient.rigid import RigidBody, RigidSet, constant_rate_motion
from app.transient.state import TransientState
from forms.kinematics import volume_weight


class VoltageDrive:
    """Multi-phase drive: U_e(t) = A_e sin(wt + phase_e) (start at rest) or A_e cos(wt + phase_e)
    (harmonic start) on the potential DOFs of each driven electrode e, held in the Function the
    Dirichlet condition was built from. A_e = amplitude_V * weight_e: ``amplitude_V`` is the
    largest electrode amplitude (set by the case or by the target-amplitude solve, which scales all
    phases together), ``weight_e`` in (0, 1] the electrode's share of it."""

    def __init__(self, values: fem.Function, electrodes: list[tuple[str, np.ndarray, float, float]],
                 frequency_Hz: float, cosine: bool):
        """``electrodes``: (name, potential DOFs, weight, phase [rad]) of each driven electrode."""
        self.values, self.electrodes = values, electrodes
        self.amplitude_V, self.omega = 0.0, 2 * math.pi * frequency_Hz
        self.start_phase = 0.5 * math.pi if cosine else 0.0

    def electrode_voltages_V(self, t: float) -> dict[str, float]:
        return {name: self.amplitude_V * weight * math.sin(self.omega * t + phase + self.start_phase)
                for name, _, weight, phase in self.electrodes}

    def voltage_V(self, t: float) -> float:
        """U(t) of the first driven electrode (the drive column of the time series)."""
        if not self.electrodes:
            return 0.0
        _, _, weight, phase = self.electrodes[0]
        return self.amplitude_V * weight * math.sin(self.omega * t + phase + self.start_phase)

    def __call__(self, t: float) -> None:
        values = self.values.x.array
        for _name, dofs, weight, phase in self.electrodes:
            values[dofs] = self.amplitude_V * weight * math.sin(self.omega * t + phase + self.start_phase)


class TransientModel:
    """Builds the FE part, rigid bodies and contacts of a case (no time loop)."""

    def __init__(self, case, comm, log, lock_drive: bool = True):
        """``lock_drive``: resolve a drive locked to the resonance (``transient.drive.lock``; an eigensolve), else
        keep the case's frequency (``validate`` solves nothing)."""
        from app.fe.model import build_model

        self.case, self.comm, self.log = case, comm, log
        self.cfg = cfg = case.transient
        file = case.source
        self.model = model = build_model(case, comm)
        if model.electrodes_of("floating"):
            raise CaseError(file, "electrodes", "floating electrodes are not supported by the transient analysis")
        self.drive_lock = None
        if cfg.drive.lock == "resonance" and lock_drive:
            from app.drive import drive_lock_line, locked_case
            from app.modal import resonances_near

            found = resonances_near(model, cfg.drive.frequency_Hz, cfg.drive.lock_modes)
            case, self.drive_lock = locked_case(case, found)
            self.case, self.cfg = case, case.transient
            cfg = self.cfg
            log(drive_lock_line(self.drive_lock))
        W = model.W
        self.gdim = gdim = model.mesh.geometry.dim
        weight = volume_weight(model.mesh, model.kind, case.geometry.thickness_m)
        for i, body in enumerate(cfg.bodies):
            if len(body.position_m) != gdim:
                raise CaseError(file, f"transient.bodies[{i}].position_m", f"needs {gdim} coordinates (mesh axes)")
        self.drive_point = cfg.drive.point if cfg.drive.point in case.points else None
        if cfg.drive.tip_amplitude_m is not None and self.drive_point is None:
            raise CaseError(file, "transient.drive.point", f"unknown point {cfg.drive.point!r}")
        if model.kind == "axisymmetric" and any(b.rotations for b in cfg.bodies):
            i = next(i for i, b in enumerate(cfg.bodies) if b.rotations)
            raise CaseError(file, f"transient.bodies[{i}].rotations",
                            "an axisymmetric model has no rotational DOF (no torsion); use plane_strain or 3d")
        # Dirichlet DOFs: supports, grounded regions, ground and driven electrodes (values in g).
        driven = [model.electrode_dofs[n] for n in model.electrodes_of("voltage")]
        self.drive_dofs = np.unique(np.concatenate(driven)).astype(np.int32) if driven else np.zeros(0, np.int32)
        held = [model.support_dofs, model.grounded_dofs, self.drive_dofs]
        held += [model.electrode_dofs[n] for n in model.electrodes_of("ground")]
        self.motions = build_motions(case, model)
        for i, motion in enumerate(self.motions):
            if comm.allreduce(np.intersect1d(motion.dofs, np.concatenate(held)).size) > 0:
                raise CaseError(file, f"transient.base_motions[{i}].facets",
                                "shares DOFs with a support, grounded region or electrode")
        held += [m.dofs for m in self.motions]
        dofs = np.unique(np.concatenate(held)).astype(np.int32)
        self.g = fem.Function(W)
        bc = fem.dirichletbc(self.g, dofs)
        self.total_mass_kg = model.total_mass_kg()
        gravity = np.asarray(cfg.loads.gravity_m_per_s2 or [0.0] * gdim, dtype=float)
        force = np.asarray(cfg.loads.fe_force_N or [0.0] * gdim, dtype=float)
        if gravity.size != gdim:
            raise CaseError(file, "transient.loads.gravity_m_per_s2", f"needs {gdim} components")
        if force.size != gdim:
            raise CaseError(file, "transient.loads.fe_force_N", f"needs {gdim} components")
        self.fe_acceleration = gravity + force / self.total_mass_kg
        self.translations = []
        loads = []
        for k in range(gdim):
            t_k = fem.Function(W)
            _, sub_dofs = W.sub(0).sub(k).collapse()
            t_k.x.array[np.asarray(sub_dofs)] = 1.0
            self.translations.append(np.asarray(sub_dofs))
            if self.fe_acceleration[k]:
                loads.append((ufl.action(model.mass, t_k), lambda t, s=float(self.fe_acceleration[k]): s))
        self.damping_frequency_Hz = case.damping.reference_frequency_Hz or cfg.drive.frequency_Hz
        self.nominal_voltage_V, weights = drive_weights(case)
        self.drive = VoltageDrive(self.g, [(n, model.electrode_dofs[n], weights[n],
                                            math.radians(case.electrodes[n].phase_deg))
                                           for n in model.electrodes_of("voltage")],
                                  cfg.drive.frequency_Hz, cosine=cfg.initial_state == "harmonic")
        self.fe = LinearFE(W, W.sub(0), model.mass, model.stiffness, model.damping(self.damping_frequency_Hz),
                           bcs=[bc], loads=loads, update_dirichlet=DirichletData(self.g, self.drive, self.motions))
        self.rigid = RigidSet([self._body(b, gravity) for b in cfg.bodies])
        context = BuildContext(case, model, self.fe, MidpointFields(self.fe), weight, gdim, file, self.rigid)
        interactions = build_interactions(cfg.contacts, context)
        try:
            self.system = CoupledSystem(comm, cfg.scheme.scheme(), self.fe, self.rigid, interactions)
        except ValueError as exc:
            raise CaseError(file, "transient.contacts", str(exc)) from None

    def _body(self, b, gravity) -> RigidBody:
        """A schema body -> RigidBody: held translations move at their given velocity (0: hold),
        rotations are free, spun at a constant rate or fixed."""
        n = len(b.position_m)
        velocity = b.velocity_m_per_s or [0.0] * n
        rotations = b.rotations
        angles = [r.angle_rad for r in rotations]
        rates = [r.rate_rad_per_s if r.motion != "fixed" else 0.0 for r in rotations]
        free = [False] * n if b.fixed else list(b.free_axes or [True] * n)
        free += [r.motion == "free" for r in rotations]
        if b.fixed:
            velocity = [0.0] * n
        force = np.asarray(b.applied_force_N, dtype=float) if b.applied_force_N else None
        torque = np.array([r.torque_N_m for r in rotations]) if any(r.torque_N_m for r in rotations) else None
        prescribed = None
        if not all(free):
            prescribed = constant_rate_motion(list(b.position_m) + angles, list(velocity) + rates)
        return RigidBody(b.name, b.mass_kg, b.position_m, velocity, [0.0] * n if b.fixed else gravity,
                         applied_force_N=(lambda t, f=force: f) if force is not None else None,
                         prescribed_axes=tuple(not f for f in free), prescribed=prescribed,
                         rotation_axes=tuple(r.axis for r in rotations),
                         inertia_kg_m2=tuple(r.inertia_kg_m2 for r in rotations), angle_rad=angles,
                         angular_velocity_rad_per_s=rates,
                         applied_torque_N_m=(lambda t, m=torque: m) if torque is not None else None,
                         brake_N_m_s_per_rad=tuple(r.brake_N_m_s_per_rad for r in rotations))

    # ----------------------------------------------------------- initial state
    def initial_state(self) -> tuple[TransientState, float]:
        """(state at t = 0, drive amplitude [V], the largest electrode amplitude). The harmonic start
        uses the steady state of the phasors c_e = w_e exp(i phase_e) per volt of amplitude,
        X = sum_e c_e X_e (X_e: electrode e driven alone, the others grounded), x(t) = Re[X e^{iwt}]:
        u0 = Re X, v0 = -w Im X, a0 = -w^2 Re X, all scaled by the amplitude. The target tip
        amplitude scales all phases together: amplitude = target / |X(point)|."""
        cfg, model = self.cfg, self.model
        voltage = self.nominal_voltage_V
        n = fem.Function(model.W).x.array.size
        u0, v0, a0 = np.zeros(n), np.zeros(n), np.zeros(n)
        if cfg.drive.tip_amplitude_m is not None or cfg.initial_state == "harmonic":
            if not self.drive.electrodes:
                key = "drive.tip_amplitude_m" if cfg.drive.tip_amplitude_m is not None else "initial_state"
                raise CaseError(self.case.source, f"transient.{key}",
                                "needs an electrode of kind 'voltage' (a harmonic solve)")
            x_re, x_im, amplitude_per_V = self._harmonic_per_volt()
            kill_point("harmonic_start")
            if cfg.drive.tip_amplitude_m is not None:
                voltage = target_voltage(cfg.drive.tip_amplitude_m, amplitude_per_V)
            if cfg.initial_state == "harmonic":
                omega = 2 * math.pi * cfg.drive.frequency_Hz
                u0, v0, a0 = voltage * x_re, -omega * voltage * x_im, -omega**2 * voltage * x_re
        for k, dofs in enumerate(self.translations):
            a0[dofs] += self.fe_acceleration[k]
        held = np.concatenate([self.model.support_dofs, self.model.grounded_dofs]).astype(np.int32)
        v0[held] = 0.0
        a0[held] = 0.0
        self.drive.amplitude_V = voltage
        self.drive(0.0)
        z, zd, zdd = self.rigid.initial_state()
        self._seat_bodies(u0, z)
        state = self.system.consistent_rigid_acceleration(TransientState(0.0, u0, v0, a0, z, zd, zdd))
        return state, voltage

    def _seat_bodies(self, u0: np.ndarray, z: np.ndarray) -> None:
        """Move each body with ``seat_on`` along its free translation axis until it just touches that
        contact's surface at the initial displacement ``u0`` (in place on ``z``; it starts at rest there)."""
        for i, body in enumerate(self.cfg.bodies):
            if body.seat_on is None:
                continue
            contact = next(c for c in self.system.interactions if c.name == body.seat_on)
            axis = (body.free_axes or [True] * len(body.position_m)).index(True)
            direction = np.eye(self.gdim)[axis]
            sl = self.rigid.dofs(body.name)
            try:
                distance = contact.seat_distance_m(u0, z[sl], direction)
            except ValueError as exc:
                raise CaseError(self.case.source, f"transient.bodies[{i}].seat_on", str(exc)) from None
            z[sl] += distance * direction
            excluded = (f" (largest excluded initial gap {contact.largest_reference_gap_m * 1e6:.4g} um)"
                        if contact.exclude_initial_gap else "")
            self.log(f"transient: body {body.name!r} seated on {contact.name!r}: moved {distance * 1e6:.6g} um along "
                     f"axis {axis}{excluded}")

    def resume_drive(self, voltage_V: float) -> None:
        """Drive amplitude of a resumed run (saved in the checkpoint: no harmonic solve)."""
        self.drive.amplitude_V = voltage_V

    def _harmonic_per_volt(self):
        """Local (with ghosts) arrays Re X, Im X of the steady state per volt of drive amplitude
        (all electrodes with their weights and phases), and |X| at the drive point."""
        from app.fe.operators import Operators

        # the transient's own K, M, C (same forms, assembled without BCs): no second assembly
        ops = Operators(self.fe.K, self.fe.M, self.fe.C)
        x_re, x_im, at_point = 0.0, 0.0, 0.0
        for name, _, weight, phase in self.drive.electrodes:
            e_re, e_im, point = self._harmonic_of_electrode(ops, name)
            c = weight * complex(math.cos(phase), math.sin(phase))
            x_re = x_re + (c.real * e_re - c.imag * e_im)
            x_im = x_im + (c.imag * e_re + c.real * e_im)
            at_point = at_point + c * point
        amplitude = abs(at_point) if self.drive_point else float("nan")
        return x_re, x_im, amplitude

    def _harmonic_of_electrode(self, ops, name: str):
        """(Re, Im of the steady state, complex displacement at the drive point) per volt on
        electrode ``name`` alone: the other driven electrodes are grounded (app.harmonic drives
        every 'voltage' electrode of the model it is given with one voltage)."""
        from app.harmonic import HarmonicSolver

        model = self.model
        if len(self.drive.electrodes) > 1:
            electrodes = {n: (e if n == name or e.kind != "voltage"
                              else dataclasses.replace(e, kind="ground", amplitude_V=None, phase_deg=0.0))
                          for n, e in self.case.electrodes.items()}
            model = copy.copy(model)
            model.case = dataclasses.replace(self.case, electrodes=electrodes)
        # 1 V at phase 0 on this electrode: its own amplitude_V and phase_deg enter through the
        # weight and phasor c_e of _harmonic_per_volt (HarmonicSolver's default phasors would apply
        # them a second time)
        solver = HarmonicSolver(model, ops, 1.0, prefix="transient_harmonic_", phasors={name: 1.0 + 0.0j})
        point = solver.solve(self.cfg.drive.frequency_Hz)
        out = []
        for vec in (solver.x_full_re, solver.x_full_im):
            f = fem.Function(model.W)
            petsc_vector(f).array_w[:] = vec.array_r
            f.x.scatter_forward()
            out.append(f.x.array.copy())
        at_point = point.displacement_m[self.drive_point] if self.drive_point else 0.0
        solver.destroy()
        return out[0], out[1], at_point


class PointSampler:
    """The named points' displacement components as fixed linear functionals of the local u-phi
    array (owned + ghosts): value = sum_j w_j x_j over the DOFs of the point's cell, the weights
    w_j (basis functions at the point) evaluated once. Gives ``model.point_values`` without copying
    the displacement out of the mixed vector and without ``Function.eval`` in every step."""

    def __init__(self, model):
        self.comm = model.mesh.comm
        self.points = {}
        V, parent = model.W.sub(0).collapse()     # the displacement space, its DOFs in W
        parent = np.asarray(parent)
        bs = V.dofmap.bs
        unit = fem.Function(V)
        for name, (probe, comp) in model.point_probes.items():
            dofs = weights = None
            if probe.cell is not None:
                cell = np.array([probe.cell], dtype=np.int32)
                local = (V.dofmap.cell_dofs(probe.cell)[:, None] * bs + np.arange(bs)).reshape(-1)
                weights = np.zeros(local.size)
                for j, d in enumerate(local):
                    unit.x.array[:] = 0.0
                    unit.x.array[d] = 1.0
                    weights[j] = np.asarray(unit.eval(probe.point.reshape(1, 3), cell)).reshape(-1)[comp]
                dofs = parent[local]
            self.points[name] = (probe.owner, dofs, weights)

    def values(self, x: np.ndarray) -> dict[str, float]:
        out = {}
        for name, (owner, dofs, weights) in self.points.items():
            value = float(weights @ x[dofs]) if dofs is not None else None
            out[name] = value if self.comm.size == 1 else self.comm.bcast(value, root=owner)
        return out


def units(tm: TransientModel, case) -> dict[str, str]:
    units = {S.TIME: "s", S.STEP: "s", S.DRIVE: "V"}
    for name in case.points:
        units[S.point_displacement(name)] = "m"
    if len(tm.drive.electrodes) > 1:
        for name, *_ in tm.drive.electrodes:
            units[S.electrode_voltage(name)] = "V"
    for b in tm.rigid.bodies:
        units.update(S.body_columns(b.name))
        if b.rotation_axes:
            units[S.body_angle(b.name)] = "rad (" + ", ".join(b.rotation_axes) + ")"
            units[S.body_angular_velocity(b.name)] = "rad/s (" + ", ".join(b.rotation_axes) + ")"
    for c in tm.system.interactions:
        units.update(c.columns())
        units[S.contact_dissipated(c.name)] = "J (damping and friction, since t = 0)"
    return units


def plot_spec(case, point: str | None, bodies: list[str], contacts: list[str], tier: str = "") -> dict:
    """What the time-series plots of a transient run show (``results["plot"]``, read again by
    ``piezodyn plot DIR``): drive point, free bodies, contacts and the title (case, downforce)."""
    downforce = float(np.linalg.norm(np.asarray(case.transient.loads.fe_force_N or [0.0])))
    title = f"{Path(case.source).stem}{tier}, downforce {downforce:.3g} N"
    return {"point": point, "bodies": bodies, "contacts": contacts, "title": title}


def build(case, comm, log, lock_drive: bool = True) -> TransientModel:
    """The transient model of ``case``: every input check of the transient analysis, including those that need the
    mesh (``piezodyn validate`` calls this too, with ``lock_drive = False``: nothing solved)."""
    file, cfg = case.source, case.transient
    if cfg.drive.tip_amplitude_m is not None and not any(e.kind == "voltage" for e in case.electrodes.values()):
        raise CaseError(file, "transient.drive.tip_amplitude_m", "needs an electrode of kind 'voltage' to drive")
    for i, c in enumerate(cfg.contacts):
        for key in ("direction", "normal"):
            vector = getattr(c, key, None)
            if vector is not None and not np.any(np.asarray(vector, dtype=float)):
                raise CaseError(file, f"transient.contacts[{i}].{key}", "must not be the zero vector")
    return TransientModel(case, comm, log, lock_drive)
