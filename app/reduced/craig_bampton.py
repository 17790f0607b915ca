"""Craig-Bampton reduction of a piezoelectric FE model (the modal-reduced tier's basis).

Why Craig-Bampton: contacts act only on a few "interface" displacement DOFs (the drill tip's axis
node, a motor stator's contact band). The basis keeps those DOFs as physical coordinates, so a
contact evaluates its gap and force on them exactly as in the FE tier, and the reduced equations of
those coordinates are the force balance at the interface. The error of the reduced model is then
that of the fixed-interface modes left out: with the interface held, the truncation error of a
response with spectrum below omega is bounded by the first mode not kept, (omega / omega_{k+1})^2
in the static limit (Craig & Bampton 1968; Bampton & Craig, AIAA J. 6 (1968) 1313; the a-priori
bound of Elssel & Voss for the eigenvalues). A free-interface basis needs residual flexibility at
the contact DOFs to reach the same accuracy and loses the physical interface coordinates.

Piezoelectric coupling is kept by treating every electrode as one more boundary coordinate: its
potential is an input (driven electrode) or a free coordinate with the zero-charge condition
(floating electrode), and its static "electrode mode" carries the quasi-static deformation the
voltage causes. Charges are outputs: Q_e = -1_e^T K x, the same functional the FE tier uses.

With x the full u-phi vector (every DOF, Dirichlet ones zero):

    x = T q,   T = [Psi_B | Psi_E | Phi],   q = [u_B ; V_E ; eta]

* Psi_B: one static constraint mode per interface DOF b: x_b = 1, every other interface DOF,
  every electrode and every Dirichlet DOF 0, interior K_II x_I = -K_Ib (one factorisation of the clamped K).
* Psi_E: one static electrode mode per electrode e: potential 1 on e, 0 on the other boundaries.
* Phi: fixed-interface normal modes K_II phi = omega^2 M_II phi (interface, electrodes and
  supports held; interior potential DOFs are massless and condensed by the eigensolver), mass
  normalised, the lowest ``n_modes`` or all below ``cutoff_Hz``.
* Optional enrichment (``n_enrich``): the full model's own modes nearest a frequency (the drive),
  with the interface free and the electrodes held (short circuit, as a driven transient sees them),
  less their constraint-mode part, M-orthogonalised against Phi. With those modes in span(T),
  Rayleigh-Ritz returns their eigenpairs exactly. Why: a drive within a few damping bandwidths of a
  resonance (the motor's F(1,4), zeta 0.2 %) makes the response steep in the detuning, and the
  Craig-Bampton frequency converges from above slowly in the number of modes and interface nodes
  (+0.14-0.39 % on the motor's coarse stator, a 23-48 % smaller wave; docs/motor-studies.md).

Reduced operators are Galerkin projections K_r = T^T K T, M_r = T^T M T, C_r = T^T C T: the damping
is the FE model's own C (Rayleigh + material Q), projected, not a guessed modal ratio. Everything
is computed with PETSc/SLEPc on the FE model's partition; the reduced matrices (small, dense) are
replicated on every rank.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from app.errors import NumericalFailure
from app.fe.constraints import ConstraintSet
from app.fe.eigen import block_shift_invert, direct_factor, symmetric_factor

REDUCTION_PREFIX = "reduction_"
MAX_MODES = 2000
#: static modes solved per MUMPS call (a dense block of right-hand sides: 64 columns of 130 k DOFs, 67 MB)
STATIC_BLOCK = 64
#: vectors per step of the block shift-invert eigensolver (app/fe/eigen.py block_shift_invert): one MUMPS solve with
#: this many right-hand sides per step. A wider block costs less per vector solved but grows the Krylov space faster
#: than it converges: the motor's 28 fixed-interface pairs took 176 vectors with 8 a block, 256 with 16, 336 with 24
#: (BENCHMARKS.md, issue 27); 4 to 12 cost alike
EIGEN_BLOCK = 8


@dataclass
class ReducedBasis:
    """The projected model. Coordinates: ``n_interface`` interface displacements [m] (in the order
    of ``interface_global_dofs``), one potential [V] per electrode (``electrodes``), then
    ``n_modes`` modal amplitudes [sqrt(kg) m]."""

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray | None
    interface_global_dofs: np.ndarray
    electrodes: list[str]                   # input coordinates: driven electrodes, then base-motion patterns
    mode_frequencies_Hz: np.ndarray
    charge_rows: dict[str, np.ndarray]      # Q_e [C] = charge_rows[e] @ q
    columns: list[PETSc.Vec] = field(repr=False)   # T, full u-phi numbering
    comm: MPI.Comm = field(repr=False, default=None)
    #: the full model's modes put in the basis (``n_enrich``), electrodes held [Hz]
    enrichment_frequencies_Hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (wall, CPU) time of each step of the reduction [s] (logged by app/reduced/model.py; BENCHMARKS.md, issue 27)
    phases: dict = field(default_factory=dict)

    @property
    def n_interface(self) -> int:
        return int(self.interface_global_dofs.size)

    @property
    def size(self) -> int:
        return self.K.shape[0]

    @property
    def n_modes(self) -> int:
        return int(self.mode_frequencies_Hz.size)

    def electrode_index(self, name: str) -> int:
        return self.n_interface + self.electrodes.index(name)

    def project_vector(self, f: PETSc.Vec) -> np.ndarray:
        """T^T f for a full-numbering load vector f (owned entries) [N per coordinate]."""
        local = np.array([c.array_r @ f.array_r for c in self.columns])
        return self.comm.allreduce(local, op=MPI.SUM)

    def project_functional(self, weights_local: np.ndarray) -> np.ndarray:
        """Row r with r @ q = sum_i w_i x_i, for weights on the owned DOFs (e.g. a point sampler)."""
        local = np.array([c.array_r @ weights_local for c in self.columns])
        return self.comm.allreduce(local, op=MPI.SUM)

    def expand(self, q: np.ndarray, out: PETSc.Vec) -> None:
        """out <- T q (owned entries)."""
        out.set(0.0)
        for value, column in zip(q, self.columns):
            if value:
                out.axpy(float(value), column)

    def destroy(self) -> None:
        for column in self.columns:
            column.destroy()
        self.columns = []


def _owned_rows(K: PETSc.Mat, global_dofs: np.ndarray) -> np.ndarray:
    lo, hi = K.getOwnershipRange()
    return global_dofs[(global_dofs >= lo) & (global_dofs < hi)]


def reduce_model(K: PETSc.Mat, M: PETSc.Mat, C: PETSc.Mat | None, W, fixed_local: np.ndarray,
                 interface_global_dofs: np.ndarray, electrode_local: dict[str, np.ndarray],
                 n_modes: int | None = None, cutoff_Hz: float | None = None,
                 damping_vectors: bool = True, n_enrich: int = 0,
                 enrich_near_Hz: float | None = None,
                 patterns: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                 interface_patterns: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
                 shared_factorisation: bool = True) -> ReducedBasis:
    """Craig-Bampton basis and projected operators.

    ``K, M, C``: assembled without boundary conditions (full u-phi numbering). ``fixed_local``: local
    DOF indices (owned or ghost) held at zero (supports, grounded regions, ground electrodes).
    ``interface_global_dofs``: global indices of the kept displacement DOFs, the same array on every
    rank. ``electrode_local``: local potential DOFs of each driven or floating electrode.
    ``n_modes`` and/or ``cutoff_Hz`` choose the fixed-interface modes (both: the larger set).
    ``n_enrich`` > 0 adds the full model's ``n_enrich`` modes nearest ``enrich_near_Hz`` (interface free,
    electrodes held) to the basis. ``patterns``: prescribed displacement patterns (a base motion's spatial
    parts), name -> (local DOFs, their values at unit amplitude): each an input coordinate after the
    electrodes, its static mode the response to that pattern with every other boundary held.
    ``interface_patterns``: interface DOF -> (global DOFs, values): that interface coordinate's static mode
    prescribes this pattern instead of the DOF's unit displacement (the band interface,
    app/contact/sites.py ring_band_patterns); every DOF of a pattern is held in the fixed-interface modes.

    ``shared_factorisation`` (the default): the clamped K factorised once as LDL^T (MUMPS, symmetric indefinite), the
    static modes solved all at once on it (a dense block of right-hand sides), the fixed-interface modes by a block
    shift-invert on the same factor and the enrichment by one on an LDL^T of its own (app/fe/eigen.py
    block_shift_invert); False: an LU, one solve per static mode
    and an eigensolver with its own factorisation (the straightforward path, which tests/test_reduced_build.py holds
    the default against)."""
    if n_modes is None and cutoff_Hz is None:
        raise ValueError("give n_modes or cutoff_Hz")
    comm = K.getComm().tompi4py()
    lo, hi = K.getOwnershipRange()
    interface = np.asarray(interface_global_dofs, dtype=PETSc.IntType)
    imap = W.dofmap.index_map
    local_to_global = imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))

    def owned_global(local: np.ndarray) -> np.ndarray:
        g = local_to_global[np.asarray(local, dtype=np.int32)]
        return g[(g >= lo) & (g < hi)].astype(PETSc.IntType)

    electrodes = list(electrode_local)
    electrode_owned = {name: owned_global(d) for name, d in electrode_local.items()}
    patterns = patterns or {}
    pattern_owned = {}
    for name, (local, values) in patterns.items():
        g = local_to_global[np.asarray(local, dtype=np.int32)]
        keep = (g >= lo) & (g < hi)
        pattern_owned[name] = (g[keep].astype(PETSc.IntType), np.asarray(values, dtype=float)[keep])
    interface_patterns = interface_patterns or {}
    band_owned = np.unique(np.concatenate([np.zeros(0, np.int64)] + [
        _owned_rows(K, np.asarray(dofs, dtype=np.int64)) for dofs, _ in interface_patterns.values()])
    ).astype(PETSc.IntType)
    held = np.unique(np.concatenate([owned_global(fixed_local), _owned_rows(K, interface), band_owned]
                                    + list(electrode_owned.values())
                                    + [g for g, _ in pattern_owned.values()])).astype(PETSc.IntType)

    phases = {}
    mark = (time.perf_counter(), time.process_time())
    # One factorisation of K with every boundary DOF clamped: static constraint and electrode modes.
    clamped = K.copy()
    clamped.zeroRowsColumns(held, 1.0)
    unit_sets = []
    for g in interface:
        if int(g) in interface_patterns:
            dofs, values = interface_patterns[int(g)]
            dofs = np.asarray(dofs, dtype=np.int64)
            mine = (dofs >= lo) & (dofs < hi)
            unit_sets.append((dofs[mine].astype(PETSc.IntType), np.asarray(values, dtype=float)[mine]))
        else:
            owned = np.array([g], dtype=PETSc.IntType) if lo <= g < hi else np.zeros(0, PETSc.IntType)
            unit_sets.append((owned, np.ones(owned.size)))
    unit_sets += [(electrode_owned[name], np.ones(electrode_owned[name].size)) for name in electrodes]
    unit_sets += [pattern_owned[name] for name in patterns]
    try:
        # the default: MUMPS's symmetric indefinite LDL^T (half the LU's factor: every solve reads half as much); the
        # reference path keeps the LU it always had
        ksp = symmetric_factor(clamped, REDUCTION_PREFIX) if shared_factorisation else _lu_factor(clamped)
    except PETSc.Error as exc:
        raise NumericalFailure(f"Craig-Bampton static modes: factorisation of the clamped K failed ({exc})") \
            from None
    mark = _lap(phases, "clamped K: " + ("LDL^T" if shared_factorisation else "LU"), mark)
    static = _static_modes_block if shared_factorisation else _static_modes_one_by_one
    columns = static(K, ksp, held, unit_sets, comm)
    damping_solves = _damping_solves(C, ksp, held, columns[interface.size:interface.size + len(electrodes)]) \
        if C is not None and damping_vectors else []
    mark = _lap(phases, f"{len(unit_sets) + len(damping_solves)} static solves", mark)
    # the interior: what the boundary (interface, inputs, supports) leaves free; none (a strip whose every node
    # is interface or prescribed), no fixed-interface modes
    interior = comm.allreduce((hi - lo) - held.size, op=MPI.SUM)
    if interior > 0:
        frequencies, modes = _fixed_interface_modes(K, M, W, held - lo, n_modes, cutoff_Hz, interior,
                                                    clamped_ksp=ksp if shared_factorisation else None)
    else:
        frequencies, modes = np.zeros(0), []
    # the clamped K's factor is done with: freed before the enrichment factorises K - sigma M, so the build never
    # holds two factors at once (its peak memory is one factor's, not two)
    ksp.destroy()
    clamped.destroy()
    mark = _lap(phases, f"{len(modes)} fixed-interface modes", mark)
    enrichment_Hz = np.zeros(0)
    if n_enrich > 0:
        if enrich_near_Hz is None:
            raise ValueError("n_enrich needs enrich_near_Hz")
        support_and_electrodes = np.unique(np.concatenate([owned_global(fixed_local)]
                                                          + list(electrode_owned.values())
                                                          + [g for g, _ in pattern_owned.values()])
                                           ).astype(PETSc.IntType)
        enrichment_Hz, extra = _enrichment_vectors(K, M, W, support_and_electrodes - lo, n_enrich, enrich_near_Hz,
                                                   columns[:interface.size], interface, modes, comm, band_owned,
                                                   block=shared_factorisation)
        modes += extra
        mark = _lap(phases, f"{n_enrich} enrichment modes", mark)
    if damping_solves:
        modes += _damping_vectors(M, damping_solves, modes)
    columns += modes

    # the charge rows: the electrodes' rows of K T summed, taken while K T exists (it is as large as the basis)
    K_r, K_sums = _project(K, columns, comm, summed_rows=[electrode_owned[name] - lo for name in electrodes])
    M_r = _project(M, columns, comm)
    C_r = _project(C, columns, comm) if C is not None else None
    charge_rows = {name: -comm.allreduce(K_sums[i], op=MPI.SUM) for i, name in enumerate(electrodes)}
    _lap(phases, "damping vectors and projections", mark)
    return ReducedBasis(K_r, M_r, C_r, interface.astype(np.int64), electrodes + list(patterns), frequencies,
                        charge_rows, columns, comm, enrichment_Hz, phases)


def _lap(phases: dict, name: str, mark: tuple[float, float]) -> tuple[float, float]:
    """phases[name] = (wall, CPU) seconds since ``mark``; returns now."""
    now = (time.perf_counter(), time.process_time())
    phases[name] = (now[0] - mark[0], now[1] - mark[1])
    return now


def _enrichment_vectors(K, M, W, held_owned_local, n_enrich, near_Hz, constraint_modes, interface, modes, comm,
                        band_owned=None, block=True):
    """The full model's ``n_enrich`` modes nearest ``near_Hz`` (``held_owned_local`` held, the interface free), each
    less its constraint-mode part (so it vanishes on the interface, like Phi) and M-orthogonalised against
    ``modes`` and each other: interior vectors whose span, with the constraint modes, holds the full modes.
    With the band interface (``band_owned``: the band's owned DOFs) what is left on the band between the stations
    (the mode's band displacement less its interpolation) is set to zero: the basis holds the full mode as the
    band interface constrains it. ``block``: the block shift-invert on an LDL^T factor (``_nearest_modes_block``);
    False: SLEPc's Krylov-Schur on an LU (the reference path)."""
    from app.fe.operators import Operators
    from app.modal import solve_modes

    constraints = ConstraintSet(W, held_owned_local.astype(np.int32), [])
    try:
        if block:
            full = _nearest_modes_block(K, M, constraints, near_Hz, n_enrich, REDUCTION_PREFIX + "enrich_")
        else:
            full = solve_modes(Operators(K, M), constraints, near_Hz, n_enrich, 0.0,
                               prefix=REDUCTION_PREFIX + "enrich_eps_")
    except PETSc.Error as exc:
        raise NumericalFailure(f"basis enrichment: the eigensolver failed for {n_enrich} modes near {near_Hz:.0f} Hz "
                               f"({exc})") from None
    lo, hi = K.getOwnershipRange()
    owned = (interface >= lo) & (interface < hi)
    M_z = K.createVecLeft()
    M_phi: dict = {}
    out, frequencies = [], []
    for mode in full:
        z = mode.vector
        at_interface = np.zeros(interface.size)
        at_interface[owned] = z.getValues(interface[owned].astype(PETSc.IntType))
        at_interface = comm.allreduce(at_interface, op=MPI.SUM)
        for value, psi in zip(at_interface, constraint_modes):
            if value:
                z.axpy(-float(value), psi)
        if band_owned is not None and band_owned.size:
            z.setValues(band_owned, np.zeros(band_owned.size))
            z.assemble()
        norm0 = math.sqrt(abs(z.dot(_mult(M, z, M_z))))
        for _ in range(2):      # classical Gram-Schmidt, twice (Kahan's "twice is enough")
            for phi in modes + out:
                if id(phi) not in M_phi:        # M phi once per vector, not once per pass and per mode
                    M_phi[id(phi)] = _mult(M, phi, M.createVecLeft())
                z.axpy(-z.dot(M_phi[id(phi)]), phi)
        norm = math.sqrt(abs(z.dot(_mult(M, z, M_z))))
        frequencies.append(mode.frequency_Hz)
        if norm > 1e-8 * norm0:     # else already in the span: nothing to add
            z.scale(1.0 / norm)
            out.append(z)
        else:
            z.destroy()
    M_z.destroy()
    for vec in M_phi.values():
        vec.destroy()
    return np.array(frequencies), out


def _damping_solves(C, ksp, held, electrode_modes) -> list[PETSc.Vec]:
    """K_II^-1 (C psi_e)_I for each electrode mode psi_e (see ``_damping_vectors``), on the clamped K's factor."""
    out = []
    rhs = C.createVecLeft()
    for psi in electrode_modes:
        C.mult(psi, rhs)
        rhs.setValues(held, np.zeros(held.size))
        rhs.assemble()
        z = C.createVecRight()
        ksp.solve(rhs, z)
        if ksp.getConvergedReason() < 0:
            raise NumericalFailure(f"Craig-Bampton damping vector: the solve failed "
                                   f"(KSP reason {ksp.getConvergedReason()})")
        out.append(z)
    rhs.destroy()
    return out


def _damping_vectors(M, solves, modes) -> list[PETSc.Vec]:
    """One interior vector per electrode, K_II^-1 (C psi_e)_I (``solves``), made M-orthogonal to the kept modes.

    A voltage on a damped body also drives the damping force i omega C psi_e, whose quasi-static
    response is not in span{psi, phi} unless C is proportional to the coupled K (here C acts on the
    elastic part only: Rayleigh beta and material Q). Without this vector the real part of the
    admittance off resonance (the loss the electrical power reads) converges only like 1/n."""
    out = []
    M_phi = M.createVecLeft()
    for z in solves:
        for phi in modes + out:
            M.mult(phi, M_phi)
            z.axpy(-z.dot(M_phi) / phi.dot(M_phi), phi)
        norm = math.sqrt(abs(z.dot(_mult(M, z, M_phi))))
        if norm > 0:
            z.scale(1.0 / norm)
            out.append(z)
        else:
            z.destroy()
    M_phi.destroy()
    return out


def _mult(A, x, out):
    A.mult(x, out)
    return out


def _static_modes_one_by_one(K, ksp, held, unit_sets, comm) -> list[PETSc.Vec]:
    """One static mode per boundary set: x = 1 (or the pattern's values) on the set, 0 on every other held DOF,
    K_II x_I = -K_Ib x_b in the interior; one LU solve each (the reference path)."""
    from app.progress import Progress

    columns: list[PETSc.Vec] = []
    boundary_values = K.createVecRight()
    rhs = K.createVecLeft()
    progress = Progress(len(unit_sets), "reduction: static modes", "solves", rank=comm.rank, value_format="{:.0f}")
    for owned, values in unit_sets:
        boundary_values.set(0.0)
        boundary_values.setValues(owned, values)
        boundary_values.assemble()
        K.mult(boundary_values, rhs)
        rhs.scale(-1.0)
        rhs.setValues(held, boundary_values.getValues(held))   # clamped rows: the boundary values
        rhs.assemble()
        x = K.createVecRight()
        ksp.solve(rhs, x)
        if ksp.getConvergedReason() < 0:
            raise NumericalFailure(f"Craig-Bampton static mode: LU solve failed "
                                   f"(KSP reason {ksp.getConvergedReason()})")
        columns.append(x)
        progress.update(1)
    progress.close()
    boundary_values.destroy()
    rhs.destroy()
    return columns


def _static_modes_block(K, ksp, held, unit_sets, comm, block: int = STATIC_BLOCK) -> list[PETSc.Vec]:
    """The static modes of ``_static_modes_one_by_one``, ``block`` at a time: the right-hand sides as the columns of
    one dense matrix, solved in one call on the clamped K's factor (MatMatSolve: MUMPS's multiple dense right-hand
    sides, forward and backward substitution with matrix-matrix kernels, where one right-hand side at a time reads
    the whole factor once per mode)."""
    lo, hi = K.getOwnershipRange()
    n_local, n_global = hi - lo, K.getSize()[0]
    held_local = held - lo
    factor = ksp.getPC().getFactorMatrix()            # set up: the factor of the clamped K
    columns: list[PETSc.Vec] = []
    for first in range(0, len(unit_sets), block):
        chunk = unit_sets[first:first + block]
        size = ((n_local, n_global), (PETSc.DECIDE, len(chunk)))
        values = np.zeros((n_local, len(chunk)), order="F")
        for j, (owned, unit) in enumerate(chunk):
            values[owned - lo, j] = unit
        boundary = PETSc.Mat().createDense(size, array=values, comm=comm)
        boundary.assemble()
        rhs = K.matMult(boundary)                      # K x_b: its negative is the interior's load
        rhs_values = rhs.getDenseArray()
        rhs_values *= -1.0
        rhs_values[held_local, :] = values[held_local, :]      # clamped rows: the boundary values
        rhs.assemble()
        solution = rhs.duplicate()
        try:
            factor.matSolve(rhs, solution)
        except PETSc.Error as exc:
            raise NumericalFailure(f"Craig-Bampton static modes: the solve failed ({exc})") from None
        solved = solution.getDenseArray(readonly=True)
        for j in range(len(chunk)):
            x = K.createVecRight()
            x.array[:] = solved[:, j]
            columns.append(x)
        for mat in (boundary, rhs, solution):
            mat.destroy()
    return columns


def _fixed_interface_modes(K, M, W, held_owned_local: np.ndarray, n_modes: int | None, cutoff_Hz: float | None,
                           interior: int = MAX_MODES, clamped_ksp: PETSc.KSP | None = None):
    """Lowest fixed-interface modes (mass normalised), by shift-invert about 0. With a cutoff, every mode below it
    (and at least ``n_modes`` if given). ``clamped_ksp``: a KSP whose operator is K with the held DOFs' rows and
    columns zeroed (1 on the diagonal) and that holds its factor: the block shift-invert (``block_shift_invert``)
    solves on that factor, a block of vectors per MUMPS call. None: SLEPc's Krylov-Schur with its own LU, restarted
    for more modes while the highest lies below the cutoff (the reference path)."""
    from app.fe.operators import Operators

    constraints = ConstraintSet(W, held_owned_local.astype(np.int32), [])
    want = min(n_modes or 16, interior)
    if clamped_ksp is None:
        modes = _lowest_modes_by_restart(Operators(K, M), constraints, REDUCTION_PREFIX + "eps_", want, n_modes,
                                         cutoff_Hz, interior, W.mesh.geometry.dim)
    else:
        limit = min(MAX_MODES, interior)
        lambda_cut = (2 * math.pi * cutoff_Hz) ** 2 if cutoff_Hz is not None else -math.inf

        def wanted(lambdas: np.ndarray) -> int:
            # every Ritz value below the cutoff and the first above it (its convergence shows none is left below)
            return min(limit, max(n_modes or 0, int(np.count_nonzero(lambdas <= lambda_cut)) + 1))

        M_held = M.copy()
        constraints.apply(M_held, 0.0)
        try:
            modes = _block_modes(clamped_ksp, M, M_held, constraints, 0.0, wanted, EIGEN_BLOCK)
        except (PETSc.Error, RuntimeError) as exc:
            raise NumericalFailure(f"fixed-interface modes: the block eigensolver failed ({exc}); "
                                   f"lower reduction.cutoff_Hz / n_modes") from None
        finally:
            M_held.destroy()
    keep = [m for m in modes if (n_modes is not None and modes.index(m) < n_modes)
            or (cutoff_Hz is not None and m.frequency_Hz <= cutoff_Hz)]
    for m in modes:
        if m not in keep:
            m.vector.destroy()
    return np.array([m.frequency_Hz for m in keep]), [m.vector for m in keep]


def _block_modes(factor_ksp, M, M_held, constraints, sigma: float, wanted, block: int) -> list:
    """``block_shift_invert`` on the factor ``factor_ksp`` holds (of K - sigma M, held DOFs clamped), the pairs as
    app.modal.Mode (frequency [Hz], vector mass-normalised with the full M), ascending in frequency."""
    from app.modal import Mode

    factor = factor_ksp.getPC().getFactorMatrix()
    lambdas, X = block_shift_invert(factor, M_held, sigma, wanted, block=block)
    y = M.createVecRight()
    Mx = M.createVecLeft()
    modes = []
    for j in np.argsort(lambdas):
        if lambdas[j] <= 0.0:       # a free body's rigid-body modes (as app.modal.converged_modes, cutoff 0)
            continue
        y.array[:] = X[:, j]
        x = M.createVecRight()
        constraints.expand(y, x)
        M.mult(x, Mx)
        x.scale(1.0 / math.sqrt(abs(x.dot(Mx))))
        modes.append(Mode(math.sqrt(lambdas[j]) / (2 * math.pi), x))
    y.destroy()
    Mx.destroy()
    return modes


def _nearest_modes_block(K, M, constraints, near_Hz: float, count: int, prefix: str) -> list:
    """The ``count`` modes nearest ``near_Hz`` in frequency of K x = omega^2 M x with ``constraints``' DOFs held
    (rigid-body modes, lambda <= 0, left out): one LDL^T of K - sigma M (sigma = (2 pi near_Hz)^2, indefinite), then
    ``block_shift_invert`` on it (the default path's enrichment; the reference path: app.modal.solve_modes, SLEPc
    with an LU, which picks the same modes). Nearest in frequency is not nearest in lambda: a mode d Hz above the
    target lies (2 pi)^2 d (2 f + d) from sigma, one d Hz below (2 pi)^2 d (2 f - d); so every Ritz pair within the
    lambda-distance of the ``count``-th nearest in frequency is converged, and the ``count`` nearest in frequency
    kept (a free body's rigid-body modes, 20 kHz below a drill's drive, are nearer in lambda than its next mode
    above)."""
    sigma = (2 * math.pi * near_Hz) ** 2

    def off_target_Hz(lambdas: np.ndarray) -> np.ndarray:
        return np.where(lambdas > 0, np.abs(np.sqrt(np.abs(lambdas)) / (2 * math.pi) - near_Hz), np.inf)

    def wanted(lambdas: np.ndarray) -> int:
        distance = np.sort(off_target_Hz(lambdas))
        if not np.isfinite(distance[min(count, distance.size) - 1]):
            return min(count, lambdas.size)
        d = distance[min(count, distance.size) - 1]
        reach = (2 * math.pi) ** 2 * d * (2 * near_Hz + d)
        return max(count, int(np.count_nonzero(np.abs(lambdas - sigma) <= reach * (1 + 1e-9))))

    shifted = K.copy()
    shifted.axpy(-sigma, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    constraints.apply(shifted, 1.0)
    M_held = M.copy()
    constraints.apply(M_held, 0.0)
    ksp = None
    try:
        ksp = symmetric_factor(shifted, prefix)
        modes = _block_modes(ksp, M, M_held, constraints, sigma, wanted, max(EIGEN_BLOCK, 2 * count))
    finally:
        for obj in (ksp, shifted, M_held):
            if obj is not None:
                obj.destroy()
    off = np.array([abs(m.frequency_Hz - near_Hz) for m in modes])
    nearest = set(np.argsort(off)[:count].tolist())
    for j, mode in enumerate(modes):
        if j not in nearest:
            mode.vector.destroy()
    return [mode for j, mode in enumerate(modes) if j in nearest]


def _lu_factor(A) -> PETSc.KSP:
    """A KSP (preonly) holding MUMPS's LU of ``A``, set up (the reference path's factorisation)."""
    return direct_factor(A, REDUCTION_PREFIX, "lu")


def _lowest_modes_by_restart(ops, constraints, prefix, want, n_modes, cutoff_Hz, interior, dim):
    """The reference path: solve for ``want`` modes; while the highest lies below the cutoff, solve again from scratch
    for more (a Weyl estimate)."""
    from app.modal import solve_modes

    while True:
        # target 0: the clamped K is non-singular, so the modes nearest 0 are the lowest ones
        try:
            modes = solve_modes(ops, constraints, 0.0, want, 0.0, prefix=prefix)
        except PETSc.Error as exc:
            raise NumericalFailure(f"fixed-interface modes: SLEPc failed for {want} modes ({exc}); "
                                   f"lower reduction.cutoff_Hz / n_modes") from None
        top = modes[-1].frequency_Hz if modes else 0.0
        if cutoff_Hz is None or top > cutoff_Hz or want >= min(MAX_MODES, interior):
            return modes
        # Weyl: the count below f grows like f^dim; ask once more for what the cutoff needs (+20 %)
        estimate = int(math.ceil(1.2 * len(modes) * (cutoff_Hz / max(top, 1e-30)) ** dim)) + 8
        for m in modes:
            m.vector.destroy()
        want = min(max(estimate, 2 * want), MAX_MODES, interior)


def _project(A: PETSc.Mat, columns: list[PETSc.Vec], comm, summed_rows: list[np.ndarray] | None = None):
    """T^T A T (dense, replicated) with one allreduce. A T is one sparse times dense product (MatMatMult), which
    reads A once per few columns rather than once per column. With ``summed_rows`` (local row index arrays) also,
    for each set, the local sum of those rows of A T: A T itself is not kept, nor copied out of PETSc (at a
    million DOFs it is as large as the basis; BENCHMARKS.md, "the reduced stator's build memory")."""
    n = len(columns)
    if n == 0:
        reduced = np.zeros((0, 0))
        return reduced if summed_rows is None else (reduced, [np.zeros(0) for _ in summed_rows])
    T = np.asfortranarray(np.column_stack([c.array_r for c in columns]))
    T_mat = PETSc.Mat().createDense(((T.shape[0], A.getSize()[1]), (PETSc.DECIDE, n)), array=T, comm=comm)
    T_mat.assemble()
    AT_mat = A.matMult(T_mat)
    AT = AT_mat.getDenseArray(readonly=True)        # a view of PETSc's array: used before AT_mat is destroyed
    local = T.T @ AT
    sums = None if summed_rows is None else \
        [AT[rows].sum(axis=0) if rows.size else np.zeros(n) for rows in summed_rows]
    del AT
    AT_mat.destroy()
    T_mat.destroy()
    del T
    reduced = comm.allreduce(local, op=MPI.SUM)
    reduced = 0.5 * (reduced + reduced.T)      # symmetric up to round-off; make it exactly so
    return reduced if sums is None else (reduced, sums)


def harmonic_response(basis: ReducedBasis, frequency_Hz: float, voltages: dict[str, complex],
                      loads: np.ndarray | None = None) -> np.ndarray:
    """Complex steady-state coordinates q for driven electrode phasors ``voltages`` [V] (the other
    electrodes float: zero charge) and optional generalized loads. Driven coordinates are prescribed."""
    omega = 2 * math.pi * frequency_Hz
    D = basis.K - omega**2 * basis.M + (1j * omega * basis.C if basis.C is not None else 0.0)
    prescribed = np.array([basis.electrode_index(n) for n in voltages], dtype=int)
    free = np.setdiff1d(np.arange(basis.size), prescribed)
    q = np.zeros(basis.size, dtype=complex)
    q[prescribed] = [voltages[n] for n in voltages]
    rhs = -D[np.ix_(free, prescribed)] @ q[prescribed]
    if loads is not None:
        rhs = rhs + loads[free]
    q[free] = np.linalg.solve(D[np.ix_(free, free)], rhs)
    return q
