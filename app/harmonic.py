"""Harmonic analysis with damping on a real PETSc build.

The complex system (K - omega^2 M + i omega C) x = f is solved as the real 2x2 block system
[[A, -omega C], [omega C, A]] [x_re; x_im] = [f_re; f_im], A = K - omega^2 M, with driven electrodes
at the drive voltage (real). Admittance Y = i omega Q / V with Q the driven electrodes' charge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

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


class HarmonicSolver:
    """Solves the driven steady state at one frequency at a time, reusing one block matrix and one
    LU factorisation object (numeric refactorisation per frequency)."""

    def __init__(self, model: FEModel, ops: Operators, voltage_V: float, prefix: str = "harmonic_"):
        self.model, self.ops, self.voltage_V = model, ops, voltage_V
        self.comm = ops.K.getComm()
        driven = model.electrodes_of("voltage")
        if not driven:
            raise NumericalFailure("harmonic analysis needs an electrode of kind 'voltage'")
        self.constraints: ConstraintSet = electrical_state(model, "driven")
        self.chi = indicator(model, driven)
        x_drive = self.chi.copy()
        x_drive.scale(voltage_V)
        self.K_r = self.constraints.reduce(ops.K)
        self.M_r = self.constraints.reduce(ops.M)
        self.C_r = self.constraints.reduce(ops.C) if ops.C is not None else self.M_r.duplicate()
        if ops.C is None:
            self.C_r.zeroEntries()
        self.x_drive_r = self.constraints.reduce_vector(x_drive)
        x_drive.destroy()
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
        self.x_bc.zeroEntries()
        self.x_bc.array[: self.n_local] = self.x_drive_r.array_r
        self.rows = self._block_rows()
        self.x_full_re = ops.K.createVecRight()
        self.x_full_im = ops.K.createVecRight()
        self.y_re = self.K_r.createVecRight()
        self.y_im = self.K_r.createVecRight()

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
        self.b.zeroEntries()
        self.B.zeroRowsColumns(self.rows, diag=1.0, x=self.x_bc, b=self.b)
        self.ksp.setOperators(self.B)
        self.ksp.solve(self.b, self.y)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise NumericalFailure(f"harmonic LU solve failed at {frequency_Hz} Hz (KSP reason {reason})")
        self.y_re.array[:] = self.y.array_r[: self.n_local]
        self.y_im.array[:] = self.y.array_r[self.n_local:]
        self.constraints.expand(self.y_re, self.x_full_re)
        self.constraints.expand(self.y_im, self.x_full_im)
        q = complex(charge(self.ops.K, self.x_full_re, self.chi), charge(self.ops.K, self.x_full_im, self.chi))
        re = self.model.point_values(self.x_full_re)
        im = self.model.point_values(self.x_full_im)
        displacement = {name: complex(re[name], im[name]) for name in re}
        return HarmonicPoint(frequency_Hz, q, 1j * omega * q / self.voltage_V, displacement)

    def destroy(self):
        for obj in (self.K_r, self.M_r, self.C_r, self.A, self.Cp, self.Cm, self.nest, self.B, self.ksp,
                    self.b, self.y, self.x_bc, self.x_drive_r, self.chi, self.x_full_re, self.x_full_im,
                    self.y_re, self.y_im):
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


def run_harmonic(model: FEModel, ops: Operators, f_r: float | None, f_a: float | None, log) -> HarmonicResult:
    cfg = model.case.harmonic
    solver = HarmonicSolver(model, ops, cfg.voltage_V)
    try:
        grid = frequency_grid(model, f_r, f_a)
        points = [solver.solve(f) for f in grid]
        result = HarmonicResult(points)
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
        result.trough_Hz = float(trough_f) if i_min > i_max else None
        result.peak = solver.solve(result.peak_Hz)
        if cfg.target is not None:
            amp = abs(result.peak.displacement_m[cfg.target.point])
            result.voltage_for_target_V = cfg.target.amplitude_m / amp * cfg.voltage_V if amp > 0 else None
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
    }
    if result.points and result.points[0].displacement_m:
        for name in result.points[0].displacement_m:
            out[f"displacement_{name}_amplitude_m_per_drive"] = [abs(p.displacement_m[name]) for p in result.points]
            out[f"displacement_{name}_phase_deg"] = [math.degrees(np.angle(p.displacement_m[name]))
                                                      for p in result.points]
            out[f"displacement_{name}_at_peak_amplitude_m"] = abs(result.peak.displacement_m[name])
    if result.voltage_for_target_V is not None:
        out["voltage_for_target_amplitude_V"] = result.voltage_for_target_V
    return out
