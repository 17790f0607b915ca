"""The linear FE part of a transient model and its factorised effective matrix.

M, C and K are assembled once without boundary conditions (residuals need the full rows and
columns so that time-varying Dirichlet values, e.g. the drive voltage, act on the free DOFs). The
effective matrix K_eff = w_M M + w_C C + w_K K of the generalized-alpha scheme depends only on dt:
it is built, constrained (Dirichlet rows and columns -> identity) and LU-factorised once per distinct
dt (PETSc's LU on one rank, MUMPS on several), and kept in a small cache so the step controller
can switch between its few step sizes without refactorising.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix, assemble_vector, set_bc
from petsc4py import PETSc

from app.compat import is_mixed, petsc_vector
from forms.newmark import TimeScheme, effective_weights

KEFF_PREFIX = "transient_keff_"


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


class EffectiveOperator:
    """K_eff for one dt: the unconstrained matrix (for residuals) and an LU factorisation of the
    constrained one, plus K_eff^-1 applied to the unit vectors of the contact DOFs (the columns
    the condensed contact system needs), computed once per dt."""

    def __init__(self, fe: LinearFE, dt: float, scheme: TimeScheme, contact_global_dofs: np.ndarray):
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
        self.ksp = self.solver_type = None
        for solver_type in _solver_types(fe.comm):
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
        self._work = Abc.createVecRight()
        self.columns = self._contact_columns(contact_global_dofs)

    @staticmethod
    def _factorise(comm, A: PETSc.Mat, solver_type: str) -> PETSc.KSP | None:
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(KEFF_PREFIX)
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

    def _contact_columns(self, contact_global_dofs: np.ndarray) -> np.ndarray:
        """Local rows of K_eff^-1 E, E = unit columns at the contact DOFs (n_owned x s)."""
        n_local = self._work.getLocalSize()
        cols = np.zeros((n_local, len(contact_global_dofs)))
        rhs = self._work.duplicate()
        lo, hi = rhs.getOwnershipRange()
        for j, g in enumerate(contact_global_dofs):
            rhs.set(0.0)
            if lo <= g < hi:
                rhs.array_w[g - lo] = 1.0
            self.solve(rhs, self._work)
            cols[:, j] = self._work.array_r
        rhs.destroy()
        return cols

    def destroy(self) -> None:
        for obj in (self.ksp, self.full, self.constrained, self._work):
            obj.destroy()


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
    """Least-recently-used cache of :class:`EffectiveOperator` keyed by dt (relative 1e-12)."""

    def __init__(self, fe: LinearFE, scheme: TimeScheme, contact_global_dofs: np.ndarray, capacity: int = 8):
        self.fe = fe
        self.scheme = scheme
        self.contact_global_dofs = contact_global_dofs
        self.capacity = capacity
        self._items: OrderedDict[float, EffectiveOperator] = OrderedDict()
        self.factorisations = 0

    def get(self, dt: float) -> EffectiveOperator:
        key = float(f"{dt:.12e}")
        op = self._items.get(key)
        if op is None:
            op = EffectiveOperator(self.fe, dt, self.scheme, self.contact_global_dofs)
            self.factorisations += 1
            self._items[key] = op
            if len(self._items) > self.capacity:
                _, old = self._items.popitem(last=False)
                old.destroy()
        else:
            self._items.move_to_end(key)
        return op

    def destroy(self) -> None:
        for op in self._items.values():
            op.destroy()
        self._items.clear()


def displacement_of(function):
    """The displacement part of a FE Function (first sub-function of a mixed space, else itself)."""
    if is_mixed(function.function_space):
        return ufl.split(function)[0]
    return function
