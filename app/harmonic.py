"""Harmonic analysis with damping on a real PETSc build.

The complex system (K - omega^2 M + i omega C) x = f is solved as the real 2x2 block system
[[A, -omega C], [omega C, A]] [x_re; x_im] = [f_re; f_im], A = K - omega^2 M. Each driven electrode
e is held at its phasor V_e = A_e exp(i phase_e) (U_e(t) = A_e cos(omega t + phase_e)): the real and
imaginary parts are the Dirichlet values of the two halves. Admittance of an electrode
Y_e = i omega Q_e / V_e with Q_e its charge; the summary admittance Y = i omega sum_e Q_e / voltage_V
(for one phase at the default amplitude, the electrode's admittance). Floating electrodes report
their potential phasor (a sensor's voltage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem
from petsc4py import PETSc

from app.compat import petsc_vector
from app.errors import NumericalFailure
from app.fe.constraints import ConstraintSet
from app.fe.model import FEModel
from app.fe.operators import Operators, charge, electrical_state, indicator


@dataclass
class HarmonicPoint:
    frequency_Hz: float
    charge_C: complex
    admittance_S: complex
    displacement_m: dict[str, complex] = field(default_factory=dict)
    electrode_admittance_S: dict[str, complex] = field(default_factory=dict)
    floating_voltage_V: dict[str, complex] = field(default_factory=dict)
    electrode_charge_C: dict[str, complex] = field(default_factory=dict)
    # several driven electrodes: each one's driving-point admittance I_k / V_k with it driven alone (the others
    # held at 0 V); under a multi-phase drive an electrode's I/V also holds the other phases' coupling
    alone_admittance_S: dict[str, complex] = field(default_factory=dict)


def drive_phasors(model: FEModel, voltage_V: float) -> dict[str, complex]:
    """Phasor [V] of each driven electrode: amplitude_V (default ``voltage_V``) at phase_deg."""
    out = {}
    for name in model.electrodes_of("voltage"):
        electrode = model.case.electrodes[name]
        amplitude = voltage_V if electrode.amplitude_V is None else electrode.amplitude_V
        out[name] = amplitude * complex(math.cos(math.radians(electrode.phase_deg)),
                                        math.sin(math.radians(electrode.phase_deg)))
    return out


class HarmonicSolver:
    """Solves the driven steady state at one frequency at a time, reusing one block matrix and one
    LU factorisation object (numeric refactorisation per frequency)."""

    def __init__(self, model: FEModel, ops: Operators, voltage_V: float, prefix: str = "harmonic_",
                 phasors: dict[str, complex] | None = None):
        self.model, self.ops, self.voltage_V = model, ops, voltage_V
        self.comm = ops.K.getComm()
        driven = model.electrodes_of("voltage")
        if not driven:
            raise NumericalFailure("harmonic analysis needs an electrode of kind 'voltage'")
        self.constraints: ConstraintSet = electrical_state(model, "driven")
        self.chi = indicator(model, driven)
        self.chi_e = {name: indicator(model, [name]) for name in driven}
        self.floating_dofs = {}
        n_owned = model.W.dofmap.index_map.size_local
        for name in model.electrodes_of("floating"):
            dofs = model.electrode_dofs[name]
            self.floating_dofs[name] = dofs[dofs < n_owned][:1]
        self.K_r = self.constraints.reduce(ops.K)
        self.M_r = self.constraints.reduce(ops.M)
        self.C_r = self.constraints.reduce(ops.C) if ops.C is not None else self.M_r.duplicate()
        if ops.C is None:
            self.C_r.zeroEntries()
        self.A = self.K_r.duplicate(copy=True)
        self.Cp = self.C_r.duplicate(copy=True)
        self.Cm = self.C_r.duplicate(copy=True)
        self.nest = PETSc.Mat().createNest([[self.A, self.Cm], [self.Cp, self.A]], comm=self.comm)
        self.B = PETSc.Mat()
        self.nest.convert("aij", self.B)  # a fresh output matrix: convert(None) would work in place
        self.n_local = self.K_r.getLocalSize()[0]
        rstart = self.K_r.getOwnershipRange()[0]
        self.block_start = 2 * rstart
        self.ksp = PETSc.KSP().create(self.comm)
        self.ksp.setOptionsPrefix(prefix)
        self.ksp.setType("preonly")
        self.ksp.getPC().setType("lu")
        self.ksp.getPC().setFactorSolverType("mumps")
        self.ksp.setFromOptions()
        self.b, self.y = self.B.createVecs()[::-1]
        self.x_bc = self.b.duplicate()
        self.alone_bc = {}                  # several driven electrodes: 1 V on each alone (driving-point Y)
        if len(driven) > 1:
            for name in driven:
                self.set_phasors({other: complex(other == name) for other in driven})
                self.alone_bc[name] = self.x_bc.copy()
        self.set_phasors(drive_phasors(model, voltage_V) if phasors is None else phasors)
        self.rows = self._block_rows()
        self.x_full_re = ops.K.createVecRight()
        self.x_full_im = ops.K.createVecRight()
        self.y_re = self.K_r.createVecRight()
        self.y_im = self.K_r.createVecRight()

    def set_phasors(self, phasors: dict[str, complex]) -> None:
        """Drive phasor [V] of every driven electrode for the following solves."""
        self.phasors = dict(phasors)
        model = self.model
        self.x_bc.zeroEntries()
        for half, part in ((slice(None, self.n_local), "real"), (slice(self.n_local, None), "imag")):
            values = fem.Function(model.W)  # assigned, not summed: DOFs shared by electrodes count once
            for name, phasor in self.phasors.items():
                values.x.array[model.electrode_dofs[name]] = getattr(phasor, part)
            reduced = self.constraints.reduce_vector(petsc_vector(values))
            self.x_bc.array[half] = reduced.array_r
            reduced.destroy()

    def _block_rows(self) -> np.ndarray:
        rows = self.constraints.dirichlet_rows() - self.K_r.getOwnershipRange()[0]
        return np.concatenate([self.block_start + rows, self.block_start + self.n_local + rows]).astype(np.int32)

    def solve(self, frequency_Hz: float) -> HarmonicPoint:
        omega = 2 * math.pi * frequency_Hz
        self.K_r.copy(self.A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.A.axpy(-omega * omega, self.M_r, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self.C_r.copy(self.Cp, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.Cp.scale(omega)
        self.C_r.copy(self.Cm, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.Cm.scale(-omega)
        self.nest.assemble()
        self.nest.convert("aij", self.B)
        # each driven electrode alone: the right-hand side zeroRowsColumns would make (b = -B x off the
        # prescribed rows, x on them), formed before the rows are zeroed; solved with the same factors below
        local_rows = self.rows - self.block_start
        alone_rhs = {}
        for name, x_k in self.alone_bc.items():
            b_k = self.b.duplicate()
            self.B.mult(x_k, b_k)
            b_k.scale(-1.0)
            b_k.array[local_rows] = x_k.array_r[local_rows]
            alone_rhs[name] = b_k
        self.b.zeroEntries()
        self.B.zeroRowsColumns(self.rows, diag=1.0, x=self.x_bc, b=self.b)
        self.ksp.setOperators(self.B)
        alone = {}
        for name, b_k in alone_rhs.items():
            self.ksp.solve(b_k, self.y)
            b_k.destroy()
            alone[name] = 1j * omega * self._charges_of_solution()[name]       # I_k / (1 V)
        self.ksp.solve(self.b, self.y)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise NumericalFailure(f"harmonic LU solve failed at {frequency_Hz} Hz (KSP reason {reason})")
        charges = self._charges_of_solution()
        q = complex(charge(self.ops.K, self.x_full_re, self.chi), charge(self.ops.K, self.x_full_im, self.chi))
        re = self.model.point_values(self.x_full_re)
        im = self.model.point_values(self.x_full_im)
        displacement = {name: complex(re[name], im[name]) for name in re}
        electrode_y = {name: 1j * omega * charges[name] / self.phasors[name] for name in charges
                       if abs(self.phasors[name]) > 0}
        floating = {}
        for name, dof in self.floating_dofs.items():
            local = complex(self.x_full_re.array_r[dof[0]], self.x_full_im.array_r[dof[0]]) if dof.size else 0j
            has = self.model.comm.allreduce(1 if dof.size else 0)
            floating[name] = self.model.comm.allreduce(local) / max(has, 1)
        return HarmonicPoint(frequency_Hz, q, 1j * omega * q / self.voltage_V, displacement, electrode_y, floating,
                             charges, alone)

    def _charges_of_solution(self) -> dict[str, complex]:
        """Expand the block solution ``self.y`` into the full u-phi vectors; each driven electrode's charge [C]."""
        self.y_re.array[:] = self.y.array_r[: self.n_local]
        self.y_im.array[:] = self.y.array_r[self.n_local:]
        self.constraints.expand(self.y_re, self.x_full_re)
        self.constraints.expand(self.y_im, self.x_full_im)
        return {name: complex(charge(self.ops.K, self.x_full_re, chi), charge(self.ops.K, self.x_full_im, chi))
                for name, chi in self.chi_e.items()}

    def full_solution(self) -> tuple[PETSc.Vec, PETSc.Vec]:
        """(real, imaginary) full u-phi vectors of the last solve (owned by the solver)."""
        return self.x_full_re, self.x_full_im

    def destroy(self):
        for obj in (self.K_r, self.M_r, self.C_r, self.A, self.Cp, self.Cm, self.nest, self.B, self.ksp,
                    self.b, self.y, self.x_bc, self.chi, self.x_full_re, self.x_full_im,
                    self.y_re, self.y_im, *self.chi_e.values(), *self.alone_bc.values()):
            obj.destroy()


def golden_section(fun, lo: float, hi: float, tol: float, maximize: bool) -> float:
    """Extremum of a unimodal function on [lo, hi] to absolute tolerance ``tol``."""
    ratio = (math.sqrt(5) - 1) / 2
    sign = -1.0 if maximize else 1.0
    a, b = lo, hi
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = sign * fun(c), sign * fun(d)
    while b - a > tol:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = sign * fun(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = sign * fun(d)
    return 0.5 * (a + b)


@dataclass
class HarmonicResult:
    points: list[HarmonicPoint]
    peak_Hz: float | None = None
    trough_Hz: float | None = None
    peak: HarmonicPoint | None = None
    voltage_for_target_V: float | None = None
    drive_scale_for_target: float | None = None
    wave: dict | None = None
    wave_point: HarmonicPoint | None = None
    field_peaks: dict | None = None        # peaks per region over the cycle at the |Y| peak (app.fe.derived)
    field_scale: float | None = None       # the drive scale of those fields (to harmonic.target, else 1)
    peak_interior: bool = True          # False: |Y| is largest at an end of the sweep (no peak inside it)
    drive: dict = field(default_factory=dict)     # {electrode: [amplitude V, phase deg]} of the sweep's drive


def frequency_grid(model: FEModel, f_r: float | None, f_a: float | None) -> np.ndarray:
    cfg = model.case.harmonic
    if cfg.f_start_Hz is not None:
        grid = np.linspace(cfg.f_start_Hz, cfg.f_stop_Hz, cfg.n_points)
    elif f_r is not None:
        gap = (f_a - f_r) if f_a is not None and f_a > f_r else 0.02 * f_r
        grid = np.linspace(max(f_r - gap, 0.5 * f_r), f_a + gap if f_a else f_r + gap, cfg.n_points)
    else:
        raise NumericalFailure("harmonic analysis needs f_start_Hz/f_stop_Hz or a modal analysis")
    extra = [f for f in (f_r, f_a) if f is not None and grid[0] < f < grid[-1]]
    return np.unique(np.concatenate([grid, extra]))


def wave_circle(model: FEModel, cfg):
    """(PointSet, theta) of harmonic.wave's circle; CaseError if a point of it lies outside the mesh (so
    ``validate`` refuses it without solving: app.runner.check_case). Collective."""
    from app.modeid import PointSet, circle_points

    points, theta = circle_points(cfg.circle_radius_m, cfg.circle_height_m, cfg.n_points)
    probe = PointSet(model.mesh, points)
    if not probe.found.all():
        from app.errors import CaseError

        raise CaseError(model.case.source, "harmonic.wave.circle_radius_m", "the circle leaves the mesh")
    return probe, theta


def circle_phasors(model: FEModel, solver: HarmonicSolver, cfg) -> tuple[np.ndarray, np.ndarray]:
    """(u_cyl phasors (n_points, 3) [m], theta) of the solver's last solution round harmonic.wave's circle."""
    from app.modeid import cylindrical

    probe, theta = wave_circle(model, cfg)
    x_re, x_im = solver.full_solution()
    u_re = cylindrical(probe(model.displacement(x_re)), theta)
    u_im = cylindrical(probe(model.displacement(x_im)), theta)
    return u_re + 1j * u_im, theta


def wave_measures(model: FEModel, solver: HarmonicSolver, cfg, frequency_Hz: float,
                  circle: tuple[np.ndarray, np.ndarray] | None = None) -> dict:
    """Travelling-wave measures (app.modeid.travelling_wave) of the solver's last solution (or of
    ``circle``, its circle_phasors when already sampled)."""
    from app.modeid import travelling_wave

    u, theta = circle or circle_phasors(model, solver, cfg)
    return travelling_wave(u, theta, tuple(cfg.normal_rz), cfg.order, frequency_Hz, cfg.circle_radius_m)


def balanced_wave(model: FEModel, solver: HarmonicSolver, cfg, frequency_Hz: float) -> tuple[HarmonicPoint, dict]:
    """Solve at ``frequency_Hz`` with the solver's drive, then with harmonic.wave.balance's electrode
    trimmed (amplitude and phase) so that the order-n part of the normal displacement travelling
    against the wave vanishes; the solver keeps the trimmed drive. By superposition one extra solve
    (the trimmed electrode alone) gives the trim. Returns the trimmed point and wave measures, the
    latter with ``balance`` (the trimmed phasor) and ``nominal`` (the untrimmed drive's measures)."""
    from app.modeid import balance_factor, normal_component

    nominal = dict(solver.phasors)
    name = cfg.balance
    trimmed_set = [name, *cfg.balance_with]
    solver.solve(frequency_Hz)
    circle = circle_phasors(model, solver, cfg)
    nominal_wave = wave_measures(model, solver, cfg, frequency_Hz, circle)
    u_all = circle[0]
    solver.set_phasors({k: (v if k in trimmed_set else 0j) for k, v in nominal.items()})
    solver.solve(frequency_Hz)
    u_trimmed, _ = circle_phasors(model, solver, cfg)
    w_all, w_trimmed = (normal_component(u, tuple(cfg.normal_rz)) for u in (u_all, u_trimmed))
    try:
        factor = balance_factor(w_all - w_trimmed, w_trimmed, cfg.order)
    except ValueError:
        raise NumericalFailure(f"harmonic.wave.balance: electrode {name!r} does not drive order {cfg.order} "
                               f"at {frequency_Hz} Hz") from None
    trimmed = nominal[name] * factor
    solver.set_phasors({**nominal, **{k: nominal[k] * factor for k in trimmed_set}})
    point = solver.solve(frequency_Hz)
    wave = wave_measures(model, solver, cfg, frequency_Hz)
    wave["balance"] = {"electrode": name, "with": list(cfg.balance_with), "factor": [factor.real, factor.imag],
                       "amplitude_V": abs(trimmed), "phase_deg": math.degrees(np.angle(trimmed)),
                       "nominal_amplitude_V": abs(nominal[name]),
                       "nominal_phase_deg": math.degrees(np.angle(nominal[name]))}
    wave["nominal"] = nominal_wave
    return point, wave


def _sweep(solver, grid, comm) -> list:
    """The sweep's solves, with progress lines (a bar in a terminal, a line every 10 % otherwise)."""
    from app.progress import Progress

    progress = Progress(len(grid), "harmonic", "frequencies", rank=comm.rank, value_format="{:.0f}")
    points = []
    for f in grid:
        points.append(solver.solve(f))
        progress.update(1)
    progress.close()
    return points


def run_harmonic(model: FEModel, ops: Operators, f_r: float | None, f_a: float | None, log,
                 wave_writer=None, wave_frequency_Hz: float | None = None, response_writer=None) -> HarmonicResult:
    """Sweep, |Y| extrema, target amplitude and travelling-wave measures. The wave is evaluated at
    harmonic.wave.frequency_Hz, else ``wave_frequency_Hz`` (the runner passes the centre of the
    working mode's split pair), else f_r, else the |Y| peak. ``wave_writer(model, solver, f)``, when
    given, exports the steady wave of the solver's last solution (the runner's export).
    ``response_writer(model, solver, f, scale)``, when given, exports the response at the |Y| peak, its drive
    scaled by ``scale`` (to harmonic.target's amplitude, else 1), and returns its peaks per region
    (``result.field_peaks``)."""
    cfg = model.case.harmonic
    solver = HarmonicSolver(model, ops, cfg.voltage_V)
    try:
        grid = frequency_grid(model, f_r, f_a)
        points = _sweep(solver, grid, model.comm)
        result = HarmonicResult(points)
        result.drive = {name: [abs(v), math.degrees(np.angle(v))] for name, v in solver.phasors.items()}
        magnitude = np.array([abs(p.admittance_S) for p in points])
        i_max = int(np.argmax(magnitude))
        i_min = int(np.argmin(magnitude[i_max:])) + i_max
        cache = {}

        def abs_y(f):
            if f not in cache:
                cache[f] = solver.solve(f)
            return abs(cache[f].admittance_S)

        def bracket(i):
            return grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]

        peak_f, trough_f = grid[i_max], grid[i_min]
        if cfg.refine_extrema:
            tol = 1e-7 * grid[i_max]
            if 0 < i_max < len(grid) - 1:
                peak_f = golden_section(abs_y, *bracket(i_max), tol, maximize=True)
            if i_max < i_min < len(grid) - 1:
                trough_f = golden_section(abs_y, *bracket(i_min), tol, maximize=False)
        result.peak_Hz = float(peak_f)
        result.trough_Hz = float(trough_f) if i_max < i_min < len(grid) - 1 else None    # an interior minimum only
        result.peak_interior = 0 < i_max < len(grid) - 1
        result.peak = solver.solve(result.peak_Hz)
        if cfg.target is not None:
            amp = abs(result.peak.displacement_m[cfg.target.point])
            # linear: every electrode's phasor scales by one common factor
            result.drive_scale_for_target = cfg.target.amplitude_m / amp if amp > 0 else None
            result.voltage_for_target_V = (result.drive_scale_for_target * cfg.voltage_V
                                           if amp > 0 else None)
        if response_writer is not None:
            result.field_scale = result.drive_scale_for_target or 1.0
            result.field_peaks = response_writer(model, solver, result.peak_Hz, result.field_scale)
        if cfg.wave is not None:
            wave_f = cfg.wave.frequency_Hz or wave_frequency_Hz or f_r or result.peak_Hz
            if cfg.wave.balance is not None:
                result.wave_point, result.wave = balanced_wave(model, solver, cfg.wave, wave_f)
            else:
                result.wave_point = solver.solve(wave_f)
                result.wave = wave_measures(model, solver, cfg.wave, wave_f)
            if wave_writer is not None:
                wave_writer(model, solver, wave_f)
        log(f"harmonic: {len(grid)} frequencies + {len(cache)} refinement solves, |Y| peak at "
            f"{result.peak_Hz:.1f} Hz")
        return result
    finally:
        solver.destroy()


def harmonic_summary(result: HarmonicResult) -> dict:
    out = {
        "frequency_Hz": [p.frequency_Hz for p in result.points],
        "admittance_magnitude_S": [abs(p.admittance_S) for p in result.points],
        "admittance_phase_deg": [math.degrees(np.angle(p.admittance_S)) for p in result.points],
        "admittance_peak_Hz": result.peak_Hz,
        "admittance_trough_Hz": result.trough_Hz,
        "admittance_peak_interior": result.peak_interior,
        # what admittance_* is: j omega (the driven electrodes' total charge) / voltage_V under this drive
        "drive_phasors_V_deg": result.drive,
    }
    if result.points and result.points[0].alone_admittance_S:
        # each driven electrode alone (the others at 0 V): its driving-point admittance I_k / V_k
        for name in result.points[0].alone_admittance_S:
            y = [p.alone_admittance_S[name] for p in result.points]
            out[f"admittance_{name}_alone_magnitude_S"] = [abs(v) for v in y]
            out[f"admittance_{name}_alone_phase_deg"] = [math.degrees(np.angle(v)) for v in y]
    if result.points and result.points[0].displacement_m:
        for name in result.points[0].displacement_m:
            out[f"displacement_{name}_amplitude_m_per_drive"] = [abs(p.displacement_m[name]) for p in result.points]
            out[f"displacement_{name}_phase_deg"] = [math.degrees(np.angle(p.displacement_m[name]))
                                                      for p in result.points]
            out[f"displacement_{name}_at_peak_amplitude_m"] = abs(result.peak.displacement_m[name])
    if result.voltage_for_target_V is not None:
        out["voltage_for_target_amplitude_V"] = result.voltage_for_target_V
        out["drive_scale_for_target"] = result.drive_scale_for_target
    peak = result.peak
    if peak is not None and (len(peak.electrode_admittance_S) > 1 or peak.floating_voltage_V):
        out["electrode_admittance_at_peak_S"] = peak.electrode_admittance_S
        for name in peak.electrode_admittance_S:
            out[f"admittance_{name}_magnitude_S"] = [abs(p.electrode_admittance_S[name]) for p in result.points]
        for name in peak.floating_voltage_V:
            out[f"floating_{name}_voltage_amplitude_V"] = [abs(p.floating_voltage_V[name]) for p in result.points]
        out["floating_voltage_at_peak_V"] = peak.floating_voltage_V
    if result.wave is not None:
        wave = dict(result.wave)
        point = result.wave_point
        wave["electrode_admittance_S"] = point.electrode_admittance_S
        wave["electrode_admittance_magnitude_S"] = {k: abs(v) for k, v in point.electrode_admittance_S.items()}
        wave["floating_voltage_V"] = point.floating_voltage_V
        wave["floating_voltage_amplitude_V"] = {k: abs(v) for k, v in point.floating_voltage_V.items()}
        out["travelling_wave"] = wave
    if result.field_peaks is not None:
        # harmonic_fields.xdmf: the response at the |Y| peak with every drive phasor times field_drive_scale
        out["field_peaks"] = result.field_peaks
        out["field_frequency_Hz"] = result.peak_Hz
        out["field_drive_scale"] = result.field_scale
    return out


def wave_lines(wave: dict | None) -> list[str]:
    """Terminal lines of the travelling-wave measures."""
    if not wave:
        return []
    lines = []
    if "balance" in wave:
        b, nominal = wave["balance"], wave["nominal"]
        lines.append(f"nominal drive: min/max {nominal['travelling_wave_ratio']:.3f}; balanced: {b['electrode']} at "
                     f"{b['amplitude_V']:.4g} V, {b['phase_deg']:.2f} deg (nominal {b['nominal_amplitude_V']:.4g} V, "
                     f"{b['nominal_phase_deg']:.2f} deg)")
    lines += [f"travelling wave at {wave['frequency_Hz']:.1f} Hz: min/max {wave['travelling_wave_ratio']:.3f}, "
              f"towards {wave['direction']}, {wave['wave_speed_m_per_s']:.1f} m/s",
              f"contact ellipse: normal {wave['ellipse_normal_amplitude_m'] * 1e6:.3f} um, tangential "
              f"{wave['ellipse_tangential_amplitude_m'] * 1e6:.3f} um, phase {wave['ellipse_phase_deg']:.1f} deg"]
    for name, y in wave["electrode_admittance_magnitude_S"].items():
        lines.append(f"  |Y_{name}| = {y * 1e3:.4g} mS")
    for name, v in wave["floating_voltage_amplitude_V"].items():
        lines.append(f"  floating electrode {name}: {v:.4g} V amplitude")
    return lines
