"""The linear FE part of a transient model and its factorised effective matrix.

M, C and K are assembled once without boundary conditions (residuals need the full rows and
columns so that time-varying Dirichlet values, e.g. the drive voltage, act on the free DOFs). The
effective matrix K_eff = w_M M + w_C C + w_K K of the generalized-alpha scheme depends only on dt:
it is built, constrained (Dirichlet rows and columns -> identity) and LU-factorised once per distinct
dt (PETSc's LU on one rank, MUMPS on several), and kept in a small cache so the step controller
can switch between its few step sizes without refactorising.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Callable, Sequence

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix, assemble_vector, set_bc
from mpi4py import MPI
from petsc4py import PETSc

from app.compat import is_mixed, petsc_vector
from forms.newmark import TimeScheme, effective_weights

KEFF_PREFIX = "transient_keff_"
COLUMNS_PREFIX = "transient_columns_"   # the MUMPS factorisation that forms G on one rank
COLUMN_BLOCK = 128                      # right-hand sides per multiple-RHS solve of G
BLOCK_MIN_COLUMNS = 48                  # fewer contact DOFs: one back-substitution per column of G


class LinearFE:
    """M, C, K (PETSc, unconstrained), loads F(t) = sum_i s_i(t) F_i and Dirichlet drives.

    ``displacement_space`` is the (sub)space holding the displacement (``W.sub(0)`` of a mixed
    u-phi space, or the vector space itself); contacts act on its DOFs. ``update_dirichlet(t)``
    sets the values of the Functions/Constants the ``bcs`` were built from (e.g. the drive
    voltage) and is called before every step."""

    def __init__(self, space, displacement_space, mass, stiffness, damping=None, bcs: Sequence = (),
                 loads: Sequence[tuple] = (), update_dirichlet: Callable[[float], None] | None = None):
        self.space = space
        self.displacement_space = displacement_space
        self.comm = space.mesh.comm
        self.bcs = list(bcs)
        self.update_dirichlet = update_dirichlet
        # Compiled forms are kept so that a reference implementation (bench/) can re-assemble.
        self.forms = {"mass": fem.form(mass), "stiffness": fem.form(stiffness),
                      "damping": fem.form(damping) if damping is not None else None}
        self.M = self._assemble(self.forms["mass"])
        self.K = self._assemble(self.forms["stiffness"])
        self.C = self._assemble(self.forms["damping"]) if damping is not None else None
        self.loads = [(self._assemble_vector(form), scale) for form, scale in loads]
        index_map = space.dofmap.index_map
        self.block_size = space.dofmap.index_map_bs
        self.n_owned = index_map.size_local * self.block_size
        self.first_global = index_map.local_range[0] * self.block_size
        self.bc_local_owned = self._bc_dofs_owned()
        self.bc_global = (self.bc_local_owned + self.first_global).astype(PETSc.IntType)
        self.gdim = space.mesh.geometry.dim

    @staticmethod
    def _assemble(form):
        A = assemble_matrix(form)
        A.assemble()
        return A

    @staticmethod
    def _assemble_vector(form):
        b = assemble_vector(fem.form(form))
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return b

    def _bc_dofs_owned(self) -> np.ndarray:
        dofs = [bc.dof_indices()[0] for bc in self.bcs]
        if not dofs:
            return np.zeros(0, dtype=np.int32)
        all_dofs = np.unique(np.concatenate(dofs))
        return all_dofs[all_dofs < self.n_owned].astype(np.int32)

    def new_vector(self) -> PETSc.Vec:
        return petsc_vector(fem.Function(self.space)).copy()

    def load_N(self, t: float, out: PETSc.Vec) -> None:
        """out <- F(t) (owned entries; ghosts not updated)."""
        out.set(0.0)
        for vec, scale in self.loads:
            out.axpy(float(scale(t)), vec)

    def apply_dirichlet(self, t: float, u: PETSc.Vec) -> None:
        """Set the Dirichlet DOFs of ``u`` to their values at time t."""
        if self.update_dirichlet is not None:
            self.update_dirichlet(t)
        set_bc(u, self.bcs)

    def zero_constrained(self, r: PETSc.Vec) -> None:
        if self.bc_local_owned.size:
            r.array_w[self.bc_local_owned] = 0.0

    def translation_vectors(self) -> list[PETSc.Vec]:
        """Nodal vectors of unit rigid translations along each mesh axis (displacement DOFs only)."""
        out = []
        for k in range(self.gdim):
            f = fem.Function(self.space)
            _, dofs = self.displacement_space.sub(k).collapse()
            f.x.array[np.asarray(dofs)] = 1.0
            out.append(petsc_vector(f).copy())
        return out

    def facet_displacement_dofs(self, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Owned displacement DOFs (local indices) on the given facets, without Dirichlet DOFs, and
        the mesh axis each one belongs to."""
        fdim = self.space.mesh.topology.dim - 1
        dofs, axes = [], []
        for k in range(self.gdim):
            sub = self.displacement_space.sub(k)
            collapsed, _ = sub.collapse()
            d = fem.locate_dofs_topological((sub, collapsed), fdim, facets)[0]
            d = d[d < self.n_owned]
            dofs.append(d)
            axes.append(np.full(d.size, k))
        dofs_all, axes_all = np.concatenate(dofs), np.concatenate(axes)
        keep = ~np.isin(dofs_all, self.bc_local_owned)
        order = np.argsort(dofs_all[keep])
        return dofs_all[keep][order].astype(np.int32), axes_all[keep][order]

    def dof_coordinates(self) -> np.ndarray:
        """Reference coordinates (gdim) of the displacement DOFs, indexed by local DOF number of the
        space (rows of other DOFs stay zero)."""
        index_map = self.space.dofmap.index_map
        out = np.zeros(((index_map.size_local + index_map.num_ghosts) * self.block_size, self.gdim))
        for k in range(self.gdim):
            collapsed, dofs = self.displacement_space.sub(k).collapse()
            out[np.asarray(dofs)] = collapsed.tabulate_dof_coordinates()[:, : self.gdim]
        return out


class InterfaceRows:
    """Where the condensed step needs rows of G = K_eff^-1 E besides its own (owned) ones: the local
    DOFs (owned and ghost) that the contact forms read (``local``), and the contact DOFs. Each rank
    keeps the rows of its ``local`` DOFs; rows owned elsewhere are exchanged once per G. Built once
    per model (collective)."""

    def __init__(self, fe: LinearFE, local: np.ndarray, contact_global: np.ndarray):
        comm = fe.comm
        self.local = np.asarray(local, dtype=np.int64)
        index_map = fe.space.dofmap.index_map
        bs = fe.block_size
        blocks = index_map.local_to_global((self.local // bs).astype(np.int32)).astype(np.int64)
        mine = blocks * bs + self.local % bs
        union = np.unique(np.concatenate(comm.allgather(mine) + [np.asarray(contact_global, dtype=np.int64)]))
        lo = fe.first_global
        owned = (union >= lo) & (union < lo + fe.n_owned)
        #: local indices of this rank's owned rows of the union (contiguous in the union: ranks own
        #: increasing global ranges)
        self.owned_rows = (union[owned] - lo).astype(np.int64)
        self.union_size = union.size
        self.position = np.searchsorted(union, mine)                  # of ``local`` in the union
        self.contact_position = np.searchsorted(union, np.asarray(contact_global, dtype=np.int64))
        self.comm = comm


class EffectiveOperator:
    """K_eff for one dt: the unconstrained matrix (for residuals) and an LU factorisation of the
    constrained one, plus G = K_eff^-1 E, E the unit vectors of the s contact DOFs (the columns the
    condensed contact system needs), computed once per dt.

    G is formed with multiple right-hand sides (MUMPS, dense blocks of ``COLUMN_BLOCK`` unit vectors)
    when s >= ``BLOCK_MIN_COLUMNS``: on one rank with a MUMPS factorisation made for it (PETSc's own LU,
    faster for one back-substitution, solves one right-hand side at a time); below that, one
    back-substitution per column. Kept: G_SS (s x s, every rank), the rows at ``rows.local``
    (:class:`InterfaceRows`) and, if ``keep_all_rows``, all owned rows (transposed, s x n_owned) for the
    end-of-step update du = w - G g; without them that update is one more back-substitution."""

    def __init__(self, fe: LinearFE, dt: float, scheme: TimeScheme, contact_global_dofs: np.ndarray,
                 rows: InterfaceRows | None = None, keep_all_rows: bool = True):
        self.dt = dt
        w_m, w_c, w_k = effective_weights(dt, scheme)
        A = fe.K.copy()
        A.scale(w_k)
        A.axpy(w_m, fe.M, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        if fe.C is not None and w_c:
            A.axpy(w_c, fe.C, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        self.full = A
        Abc = A.copy()
        Abc.zeroRowsColumns(fe.bc_global, 1.0)
        self.constrained = Abc
        self._work = Abc.createVecRight()
        self.comm = fe.comm
        self.contact_global = np.asarray(contact_global_dofs)
        self.rows_layout = rows
        self.columns_t = None           # all owned rows of G, transposed (s x n_owned), or None
        self.rows = None                # G at rows.local (len(rows.local) x s)
        self.contact_block = None       # G_SS (s x s, every rank)
        self.column_solves = 0          # right-hand sides solved for G
        self.ksp = self.solver_type = None
        keep_all_rows = keep_all_rows or rows is None
        candidates = _solver_types(fe.comm)
        built = False
        if self.contact_global.size >= BLOCK_MIN_COLUMNS and candidates[0] != "mumps":
            # G first, through a MUMPS factorisation freed before the per-step one is made: the two
            # factorisations never coexist (3D: ~2 GB each at 130 k DOFs)
            mumps = self._factorise(fe.comm, Abc, "mumps", prefix=COLUMNS_PREFIX)
            if mumps is not None:
                try:
                    self._build_columns(keep_all_rows, mumps.getPC().getFactorMatrix())
                    built = True
                finally:
                    mumps.destroy()
        for solver_type in candidates:
            self.ksp = self._factorise(fe.comm, Abc, solver_type)
            if self.ksp is None:
                continue
            self.solver_type = solver_type
            if solver_type == "mumps" or self._backward_error() < 1e-10:
                break
            self.ksp.destroy()
            self.ksp = None
        if self.ksp is None:
            raise FloatingPointError(f"K_eff at dt = {dt:.3e} s could not be factorised")
        if not built:
            blocked = self.solver_type == "mumps" and self.contact_global.size >= BLOCK_MIN_COLUMNS
            self._build_columns(keep_all_rows, self.ksp.getPC().getFactorMatrix() if blocked else None)

    @property
    def columns(self) -> np.ndarray:
        """Owned rows of G = K_eff^-1 E (n_owned x s, a view)."""
        if self.columns_t is None:
            raise RuntimeError("this operator keeps G only at the interface rows")
        return self.columns_t.T

    @property
    def nbytes(self) -> int:
        """Bytes held by the dense parts of G."""
        return sum(a.nbytes for a in (self.columns_t, self.rows, self.contact_block) if a is not None)

    @staticmethod
    def _factorise(comm, A: PETSc.Mat, solver_type: str, prefix: str = KEFF_PREFIX) -> PETSc.KSP | None:
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType(solver_type)
        if solver_type == "petsc":
            pc.setFactorOrdering("amd")
        ksp.setFromOptions()
        try:
            ksp.setUp()     # a zero pivot shows in the checked solve (KSP reason DIVERGED_PC_FAILED)
        except PETSc.Error:
            ksp.destroy()
            return None
        return ksp

    def _backward_error(self) -> float:
        """Normwise backward error |A x - b| / (|A| |x| + |b|) of one solve with a fixed
        pseudo-random solution (inf if the solve fails): PETSc's own LU does not pivot, so its
        factorisation is checked before it is used (a failure falls back to MUMPS)."""
        A = self.constrained
        x_true, b = A.createVecRight(), A.createVecLeft()
        lo, hi = x_true.getOwnershipRange()
        x_true.array_w[:] = np.sin(np.arange(lo, hi) * 0.7 + 0.3)
        A.mult(x_true, b)
        x, r = x_true.duplicate(), b.duplicate()
        try:
            self.ksp.solve(b, x)
            ok = self.ksp.getConvergedReason() >= 0
        except PETSc.Error:
            ok = False
        error = np.inf
        if ok:
            A.mult(x, r)
            r.axpy(-1.0, b)
            error = r.norm() / (A.norm(PETSc.NormType.INFINITY) * x.norm() + b.norm())
        for v in (x_true, b, x, r):
            v.destroy()
        return float(error) if np.isfinite(error) else np.inf

    def solve(self, rhs: PETSc.Vec, out: PETSc.Vec) -> None:
        self.ksp.solve(rhs, out)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise FloatingPointError(f"K_eff solve failed (KSP reason {reason})")

    # ------------------------------------------------------------------ G = K_eff^-1 E
    def _build_columns(self, keep_all_rows: bool, factor: PETSc.Mat | None) -> None:
        """G with multiple right-hand sides through the MUMPS ``factor``, or (None) one back-substitution
        with the per-step factorisation per column."""
        contact = self.contact_global
        s_count = contact.size
        n_local = self._work.getLocalSize()
        layout = self.rows_layout
        if keep_all_rows:
            self.columns_t = np.empty((s_count, n_local))
        owned_rows = layout.owned_rows if layout is not None else np.zeros(0, dtype=np.int64)
        interface_t = np.empty((s_count, owned_rows.size))
        blocks = (self._multiple_columns(factor, contact) if factor is not None
                  else self._single_columns(contact)) if s_count else ()
        for start, block in blocks:
            stop = start + block.shape[1]
            if self.columns_t is not None:
                self.columns_t[start:stop] = block.T
            interface_t[start:stop] = block[owned_rows].T
        if layout is None:
            self.contact_block = self._gather_contact_rows()
            return
        union_t = interface_t if self.comm.size == 1 else np.hstack(self.comm.allgather(interface_t))
        self.rows = np.ascontiguousarray(union_t[:, layout.position].T)
        self.contact_block = np.ascontiguousarray(union_t[:, layout.contact_position].T)

    def _gather_contact_rows(self) -> np.ndarray:
        lo, hi = self._work.getOwnershipRange()
        mine = self.contact_global[(self.contact_global >= lo) & (self.contact_global < hi)] - lo
        rows = self.columns_t[:, mine].T
        return rows if self.comm.size == 1 else np.vstack(self.comm.allgather(rows))

    def _single_columns(self, contact):
        rhs = self._work.duplicate()
        lo, hi = rhs.getOwnershipRange()
        try:
            for j, g in enumerate(contact):
                rhs.set(0.0)
                if lo <= g < hi:
                    rhs.array_w[g - lo] = 1.0
                self.solve(rhs, self._work)
                self.column_solves += 1
                yield j, self._work.array_r.reshape(-1, 1)
        finally:
            rhs.destroy()

    def _multiple_columns(self, factor: PETSc.Mat, contact):
        n_local = self._work.getLocalSize()
        n_global = self._work.getSize()
        lo, hi = self._work.getOwnershipRange()
        for start in range(0, contact.size, COLUMN_BLOCK):
            cols = contact[start:start + COLUMN_BLOCK]
            k = cols.size
            B = PETSc.Mat().createDense(((n_local, n_global), (PETSc.DECIDE, k)), comm=self.comm)
            B.setUp()
            values = B.getDenseArray()
            values[:] = 0.0
            mine = (cols >= lo) & (cols < hi)
            values[cols[mine] - lo, np.flatnonzero(mine)] = 1.0
            B.assemble()
            X = B.duplicate()
            try:
                factor.matSolve(B, X)
                self.column_solves += k
                yield start, np.array(X.getDenseArray(readonly=True))
            finally:
                B.destroy()
                X.destroy()

    def destroy(self) -> None:
        for obj in (self.ksp, self.full, self.constrained, self._work):
            obj.destroy()
        self.columns_t = self.rows = self.contact_block = None


def _solver_types(comm) -> list[str]:
    """LU packages to try for K_eff, in order. One rank: PETSc's own sparse LU (AMD ordering),
    whose back-substitution is ~5x faster than MUMPS' at the drill scene's 11k DOFs (0.42 vs
    2.2 ms, BENCHMARKS.md), with MUMPS as the fallback if it meets a zero pivot or is inaccurate;
    several ranks: MUMPS. ``-transient_keff_pc_factor_mat_solver_type`` overrides."""
    opts = PETSc.Options()
    name = KEFF_PREFIX + "pc_factor_mat_solver_type"
    chosen = opts.getString(name) if opts.hasName(name) else None
    if chosen:
        return [chosen]
    return ["petsc", "mumps"] if comm.size == 1 else ["mumps"]


class EffectiveOperatorCache:
    """Least-recently-used cache of :class:`EffectiveOperator` keyed by dt (relative 1e-12).

    The dense G of an operator can be large (n_owned x s doubles per rank: 1.7 GB for the motor's
    130 k DOFs and 1 632 contact DOFs), so all of its rows are kept only while the cache's share stays
    within ``memory_budget_bytes`` per rank (default: a quarter of the machine's memory divided by
    the ranks; ``PIEZODYN_COLUMNS_BUDGET_MB`` overrides); an operator beyond it keeps G at the
    interface rows only. A step size the run returns to after a cut-back finds its operator here."""

    def __init__(self, fe: LinearFE, scheme: TimeScheme, contact_global_dofs: np.ndarray, capacity: int = 8,
                 rows: InterfaceRows | None = None, memory_budget_bytes: float | None = None):
        self.fe = fe
        self.scheme = scheme
        self.contact_global_dofs = contact_global_dofs
        self.capacity = capacity
        self.rows = rows
        self.memory_budget_bytes = (memory_budget_bytes if memory_budget_bytes is not None
                                    else default_columns_budget_bytes(fe.comm))
        self._items: OrderedDict[float, EffectiveOperator] = OrderedDict()
        self.factorisations = 0

    def get(self, dt: float) -> EffectiveOperator:
        key = float(f"{dt:.12e}")
        op = self._items.get(key)
        if op is None:
            if len(self._items) >= self.capacity:
                _, old = self._items.popitem(last=False)
                old.destroy()
            held = sum(o.nbytes for o in self._items.values())
            wanted = self.fe.n_owned * len(self.contact_global_dofs) * 8
            keep_all = self.fe.comm.allreduce(held + wanted <= self.memory_budget_bytes, op=MPI.LAND)
            op = EffectiveOperator(self.fe, dt, self.scheme, self.contact_global_dofs, rows=self.rows,
                                   keep_all_rows=keep_all)
            self.factorisations += 1
            self._items[key] = op
        else:
            self._items.move_to_end(key)
        return op

    def destroy(self) -> None:
        for op in self._items.values():
            op.destroy()
        self._items.clear()


def default_columns_budget_bytes(comm) -> float:
    """Bytes per rank for the cached operators' dense G: ``PIEZODYN_COLUMNS_BUDGET_MB``, else a quarter
    of the physical memory shared by the ranks."""
    value = os.environ.get("PIEZODYN_COLUMNS_BUDGET_MB")
    if value:
        return float(value) * 2**20
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8 * 2**30
    return 0.25 * total / comm.size


def displacement_of(function):
    """The displacement part of a FE Function (first sub-function of a mixed space, else itself)."""
    if is_mixed(function.function_space):
        return ufl.split(function)[0]
    return function
