"""One implicit step of FE + rigid bodies + penalty contact: the FE part is condensed onto the
contact DOFs, and PETSc SNES solves the small nonlinear system that remains.

The FE equations of a step are linear: with the correction du = u_{n+1} - u_pred to a predictor,
their residual is r0 + A du + E rc_S, where A = K_eff is constant for a given dt (factorised once
by :class:`EffectiveOperator`), E holds the unit columns of the s contact DOFs and rc_S is the
contact residual on them. Every solution is therefore

    du = w - G g,    w = -A^-1 r0 (one back-substitution per step),  G = A^-1 E (once per dt),

for the contact forces g the FE side must carry. Newton then runs on the s + m unknowns (g, dz),
dz the rigid-body increments, with the residual

    F_g = rc_S(w_S - G_SS g, dz) - g,    F_z = r_z(w_S - G_SS g, dz)    (forces, N)

and the dense Jacobian [[-(I + Kss G_SS), B], [-L G_SS, Kzz]] (Kss, B: contact tangent w.r.t. the
contact DOFs and the rigid DOFs; L, Kzz: rigid rows). The full FE residual at du = w - G g is
E (rc_S - g), so |(F_g, F_z)| is the norm of the full residual and the tolerances mean what they
meant for the full system. A contact iteration costs an n x s product, no back-substitution, no
mat-vec and no refactorisation. SNES (prefix ``transient_``) drives the iteration (line search,
converged reason) through a shell Jacobian and a shell preconditioner holding the dense LU.
`demos/demo_fullspace.py` keeps the same step as a Newton iteration on all n + m unknowns,
the reference the tests and ``bench/`` compare against.

The right-hand side avoids the u_n / (beta dt^2)-sized terms of the textbook form: with the
predictor u_pred = u_n + dt v_n + dt^2/2 a_n (Dirichlet values of t_{n+1} set, their change
delta), a_pred = a_n + delta / (beta dt^2) and v_pred = v_n + dt a_n + gamma delta / (beta dt), so

    r0 = M [(1 - a_m) a_pred + a_m a_n] + C [(1 - a_f) v_pred + a_f v_n]
         + K [(1 - a_f) u_pred + a_f u_n] - F(t_{n+1-a_f})

is three mat-vecs of physical-size vectors, free of cancellation.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from app.blas import limit_blas_threads
from app.compat import petsc_vector
from app.transient.active_set import CondensedJacobian, ContactTangent, RigidJacobian, subtract_rows
from app.transient.fe import EffectiveOperatorCache, InterfaceRows, LinearFE
from app.transient.kinematics import (
    increment_kinematics,
    predictor_arguments,
    rigid_step_start,
    scheme_factors,
    step_kinematics,
    step_kinematics_at,
    step_rates,
    taylor_predictor,
)
from app.transient.rigid import RigidSet
from app.transient.state import TransientState
from forms.newmark import (
    TimeScheme,
    acceleration_per_displacement,
    midpoint,
    velocity_per_displacement,
)

_EPS = float(np.finfo(float).eps)
SNES_PREFIX = "transient_"
SNES_DEFAULTS = {
    "snes_type": "newtonls",
    # Semi-smooth Newton with backtracking: the penalty residual is piecewise smooth with an exact
    # tangent, so full steps are taken once the active set settles; where they are not a descent
    # (velocity-weakening friction, mu falling from mu_s to mu_d with slip speed, made full steps
    # cycle against a curved obstacle) the search shortens them. On the condensed system a trial
    # step costs a contact evaluation and a small dense product. Failure -> cut-back (control.py).
    "snes_linesearch_type": "bt",
    "snes_rtol": 1e-10,
    "snes_stol": 1e-14,
    # Regularised Coulomb friction turns over within ~1e-11 m of displacement per step where the
    # slip reverses inside a contact (a travelling-wave drive, 0.1 mm/s regularisation): Newton
    # with backtracking gets there in up to ~40 iterations, far cheaper than a cut-back that ends
    # in the same place (a steel strip under a slider: 418 cut-backs at 20 iterations, none at 60;
    # BENCHMARKS.md).
    "snes_max_it": 60,
}


class CoupledSystem:
    """Residual, Jacobian and condensed solve of one generalized-alpha step."""

    def __init__(self, comm, scheme: TimeScheme, fe: LinearFE | None, rigid: RigidSet, interactions=(),
                 relative_force_tolerance: float = 1e-10, active_set: bool = True):
        """``interactions``: objects of the :class:`app.transient.interactions.Interaction` protocol.
        ``active_set=False`` solves the dense Newton system on all contact DOFs in every iteration and
        evaluates every FE DOF at every iterate (the previous step; the tests' reference)."""
        limit_blas_threads()    # MPI ranks are the parallelism (see app.blas)
        self.comm, self.scheme, self.fe, self.rigid = comm, scheme, fe, rigid
        self.interactions = list(interactions)
        names = [c.name for c in self.interactions]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate interaction names in {names}")
        self.relative_force_tolerance = relative_force_tolerance
        self.n_fe = fe.n_owned if fe is not None else 0
        self.m = rigid.size
        self.m_local = self.m if comm.rank == 0 else 0
        self.active_set = active_set
        # per-iterate bookkeeping, formed once: the mass factor of the new acceleration, the prescribed axes, brakes
        self._mass_new = rigid.mass_diagonal * (1 - scheme.alpha_m)
        self._mass_old = rigid.mass_diagonal * scheme.alpha_m
        self._fixed_axes = np.flatnonzero(~rigid.free_mask)
        self._braked = bool(np.any(rigid.damping_diagonal))
        self._fe_contacts = [c for c in self.interactions if c.fe_coupled]
        self._rigid_links = [c for c in self.interactions if not c.fe_coupled]
        self._rigid_jacobians = {}      # RigidJacobian by its Kzz (the same while dt and the links' states stay)
        self._rigid_jacobians_by_state = {}     # the same by (c_acc, c_vel, the links' tangent keys)
        self._rigid_diagonal_now = None
        self._setup_contact_dofs()
        for c in self.interactions:
            c.bind(self)
        # the FE DOFs the contact forms read: evaluated at every contact iterate, the rest once per step
        evaluation = self._evaluation_dofs() if fe is not None and active_set else None
        self._rows_layout = InterfaceRows(fe, evaluation, self.contact_global) if evaluation is not None else None
        self.cache = (EffectiveOperatorCache(fe, scheme, self.contact_global, rows=self._rows_layout)
                      if fe is not None else None)
        # the shared mid-point fields, kept up to date only if an interaction's forms read them
        self.fields = list({id(c.fields): c.fields for c in self.interactions
                            if getattr(c, "reads_fields", hasattr(c, "fields"))}.values())
        self._field_constants = None
        # bumped whenever the mid-point quantities (u_mid, v_mid, z_mid, zd_mid) change: an interaction may keep
        # what it derived from them while the version stays (NodeContact._at_iterate)
        self.iterate_version = 0
        self.rigid_version = 0          # the same for the rigid mid-point quantities (z_mid, zd_mid) alone
        self._rigid_values_version = None       # rigid_version of the floats rigid_mid_values keeps
        if fe is not None:
            from dolfinx import fem

            self._u1 = fem.Function(fe.space)
            size = self._u1.x.array.size
            # a_{n+1}, v_{n+1}, u_mid, v_mid on the local DOFs (owned and ghost), written in place (u_mid, v_mid at
            # every DOF only for shared fields; else at the evaluation DOFs, see _fe_fields)
            self.a1, self.v1, self.u_mid, self.v_mid = np.zeros((4, size))
            self._u1_is_free = False        # _u1 holds u_pred + w of the step (set by _condense)
            self._fields_formed = False     # formed at every DOF once (the first step's predictor)
            self.translations = fe.translation_vectors()
            self._r = fe.new_vector()
            self._tmp = fe.new_vector()
            self._tmp2 = fe.new_vector()
            self._matvec_arguments = [fe.new_vector() for _ in range(3)]    # of M, K, C in the predictor residual
            self._u_pred = fe.new_vector()
            self._r0 = fe.new_vector()
            self._du = fe.new_vector()
            self._w = fe.new_vector()
        self._setup_snes()
        self.last_iterations = 0
        self.total_iterations = 0
        self.linear_steps = 0           # steps solved without SNES (no FE contact force)
        self.active_dofs = 0            # contact DOFs in the Newton systems solved (sum over Jacobians)
        self.jacobians = 0
        self.active_set_changes = 0     # Jacobians whose active set differs from the step's previous one
        self.opened_updates = 0         # Newton updates that took DOFs carrying force off the active set
        self._evaluated = self._fe_key = None
        self._residual_in_R = False
        self._fe_full = False           # the FE fields hold every DOF of the evaluated iterate
        self._jacobian = None
        self._step_count = self._jacobian_step = 0

    # ----------------------------------------------------------------- setup
    def _setup_contact_dofs(self) -> None:
        fe_contacts = [c for c in self.interactions if c.fe_coupled]
        self.contact_position = {}
        if self.fe is None or not fe_contacts:
            self.contact_local = np.zeros(0, dtype=np.int32)
            self.contact_global = np.zeros(0, dtype=PETSc.IntType)
            self.translation_S = np.zeros((0, self.rigid.gdim))
            self._S_offset = 0
            return
        axes = {}
        for c in fe_contacts:
            axes.update(zip(c.local_dofs.tolist(), c.dof_axes.tolist()))
        local = np.array(sorted(axes), dtype=np.int32)
        gathered = self.comm.allgather(local + self.fe.first_global)
        gathered_axes = self.comm.allgather(np.array([axes[d] for d in local], dtype=int))
        self.contact_local = local
        self.contact_global = np.concatenate(gathered).astype(PETSc.IntType)
        all_axes = np.concatenate(gathered_axes)
        self.translation_S = np.zeros((self.contact_global.size, self.fe.gdim))
        self.translation_S[np.arange(all_axes.size), all_axes] = 1.0
        self._S_offset = sum(g.size for g in gathered[: self.comm.rank])
        # global DOF -> position among the contact DOFs
        self.contact_position = {int(g): i for i, g in enumerate(self.contact_global)}

    def _evaluation_dofs(self) -> np.ndarray | None:
        """Local DOFs (owned and ghost) whose values the FE-coupled interactions read while Newton
        iterates: the DOFs of every cell of an exterior-facet integral of their forms, and a node
        contact's own DOFs. None (evaluate everything) for an interaction that reads anything else."""
        from dolfinx import fem

        fe = self.fe
        dofmap = fe.space.dofmap
        bs = dofmap.index_map_bs
        cell_dofs = dofmap.list.array.reshape(-1, dofmap.dof_layout.num_dofs)
        found = []
        for c in self.interactions:
            if not c.fe_coupled:
                continue
            forms = []
            for value in vars(c).values():
                items = value if isinstance(value, (list, tuple)) else [value]
                for item in items:
                    for sub in (item if isinstance(item, (list, tuple)) else [item]):
                        if isinstance(sub, fem.FormMetaClass):
                            forms.append(sub)
            if forms:
                cells = []
                for form in forms:
                    for kind in form.integral_types:
                        if kind != fem.IntegralType.exterior_facet:
                            return None
                        for i in form.integral_ids(kind):
                            cells.append(np.asarray(form.domains(kind, i)).reshape(-1, 2)[:, 0])
                cells = np.unique(np.concatenate(cells)) if cells else np.zeros(0, dtype=np.int32)
                blocks = cell_dofs[cells].reshape(-1)
                found.append((blocks[:, None] * bs + np.arange(bs)).reshape(-1))
            elif c.kind == "node":
                found.append(np.asarray(c.local_dofs))
            else:
                return None
        local = np.concatenate(found) if found else np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([local, self.contact_local])).astype(np.int64)

    def _unknowns_local(self) -> int:
        """Local size of the SNES unknown: (g, dz), held by rank 0."""
        return self.contact_global.size + self.m if self.comm.rank == 0 else 0

    def _setup_snes(self) -> None:
        sizes = (self._unknowns_local(), PETSc.DECIDE)
        self.X = PETSc.Vec().createMPI(sizes, comm=self.comm)
        self.R = self.X.duplicate()
        self._step_vector = self.X.duplicate()
        self.J = PETSc.Mat().createPython((sizes, sizes), context=_JacobianShell(self), comm=self.comm)
        self.J.setUp()
        opts = PETSc.Options()
        for key, value in SNES_DEFAULTS.items():
            if not opts.hasName(SNES_PREFIX + key):
                opts.setValue(SNES_PREFIX + key, value)
        snes = PETSc.SNES().create(self.comm)
        snes.setOptionsPrefix(SNES_PREFIX)
        snes.setFunction(self._residual_callback, self.R)
        snes.setJacobian(self._jacobian_callback, self.J, self.J)
        ksp = snes.getKSP()
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(_ShellInverse(self))
        snes.setFromOptions()
        ksp.setType("preonly")
        self.snes = snes

    # ------------------------------------------------------------- one step
    def solve_step(self, state: TransientState, dt: float) -> tuple[int, TransientState | None]:
        """Try one step from ``state``. Returns (SNES converged reason, new state or None)."""
        try:
            self._begin_step(state, dt)
            atol = self.relative_force_tolerance * self._force_scale + self._roundoff_force + 1e-300
            reason = self._contact_free_step(atol)
            if reason is None:
                self.snes.setTolerances(atol=atol)
                self.snes.solve(None, self.X)
                reason = self.snes.getConvergedReason()
                self.last_iterations = self.snes.getIterationNumber()
            else:
                self.last_iterations = 1
                self.linear_steps += 1
        except (PETSc.Error, FloatingPointError, np.linalg.LinAlgError, ValueError):
            return PETSc.SNES.ConvergedReason.DIVERGED_FUNCTION_DOMAIN, None
        self.total_iterations += self.last_iterations
        if reason <= 0:
            return reason, None
        self._evaluate(self.X)
        self._evaluate_everywhere()
        # Forces now, at the converged mid-point fields: other users of the shared fields (the
        # contact monitor, energy account) overwrite them with end-of-step values afterwards.
        self.last_forces_N = self.contact_forces_N()
        self.last_dissipation_W = {c.name: c.dissipation_power_W(self) for c in self.interactions}
        return reason, self._new_state()

    def _contact_free_step(self, atol: float):
        """A step in which no FE contact carries force, neither at the initial guess nor at the
        result, needs no contact tangent: take one Newton step with zero FE contact blocks (the
        rigid block keeps mass and Kelvin-Voigt links) without SNES and its Python callbacks, check
        the residual with the same absolute/relative test as SNES and return the converged reason;
        None (X left at a valid guess) hands the step to SNES. Same arithmetic as SNES' first full
        Newton step (which its line search takes when it reduces the residual), so the result does
        not depend on the path; if a rigid-rigid link opens or closes within the step, the residual
        test fails and SNES iterates."""
        X, R = self.X, self.R
        self._residual_callback(None, X, R)
        if self._fe_contact_active:
            return None
        norm0 = R.norm()
        if not math.isfinite(norm0):
            raise FloatingPointError("non-finite residual")
        if norm0 <= atol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        self._set_contact_free_jacobian()
        Y = self._step_vector
        self.apply_inverse(R.array_r, Y.array)
        X.axpy(-1.0, Y)
        self._residual_callback(None, X, R)
        norm1 = R.norm()
        if self._fe_contact_active or not math.isfinite(norm1):
            return None
        if norm1 <= atol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        if norm1 <= SNES_DEFAULTS["snes_rtol"] * norm0:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_RELATIVE
        return None

    def _set_contact_free_jacobian(self) -> None:
        """The Jacobian data with every FE contact block zero, as ``_jacobian_callback`` builds it
        when no FE contact is active."""
        s_count, m = self.contact_global.size, self.m
        # Kzz is a function of dt and of the rigid links' tangent state: reuse its factorisation when the links
        # say what that state is (``tangent_key``; the same on every rank: the rigid state is replicated)
        keys = [getattr(c, "tangent_key", None) for c in self._rigid_links]
        key = None if any(k is None for k in keys) else (self.c_acc, self.c_vel, *(k(self) for k in keys))
        if key is not None and None in key:     # a link on its general path: its tangent has no key
            key = None
        if key is not None and key in self._rigid_jacobians_by_state:
            if self.comm.rank == 0:
                self._jacobian = self._rigid_jacobians_by_state[key]
            return
        Kzz = self._rigid_block(np.diag(self._rigid_diagonal()))
        self._set_jacobian(ContactTangent(s_count), np.zeros((s_count, m)), np.zeros((m, s_count)), Kzz)
        if key is not None and self.comm.rank == 0:
            if len(self._rigid_jacobians_by_state) >= 16:
                self._rigid_jacobians_by_state.clear()
            self._rigid_jacobians_by_state[key] = self._jacobian

    def _rigid_diagonal(self) -> np.ndarray:
        """d r_z / d z_{n+1} of the bodies alone: inertia (1 - alpha_m) c_acc m and brake
        (1 - alpha_f) c_vel c (the brake acts on the mid-point rate)."""
        if self._rigid_diagonal_now is None:      # once a step (c_acc, c_vel)
            s = self.scheme
            self._rigid_diagonal_now = ((1 - s.alpha_m) * self.c_acc * self.rigid.mass_diagonal
                                        + (1 - s.alpha_f) * self.c_vel * self.rigid.damping_diagonal)
        return self._rigid_diagonal_now

    def _begin_step(self, state: TransientState, dt: float) -> None:
        s, fe, rigid = self.scheme, self.fe, self.rigid
        self.state0, self.dt = state, dt
        self._step_count += 1
        self._evaluated = self._fe_key = None
        self._residual_in_R = False
        self.t1 = state.t + dt
        self.t_mid = midpoint(self.t1, state.t, s.alpha_f)
        self.c_acc = acceleration_per_displacement(dt, s)
        self.c_vel = velocity_per_displacement(dt, s)
        self._factors = scheme_factors(dt, s)
        if self._field_constants != (self.c_vel, s.alpha_f):     # set the forms' constants when dt changes
            for f in self.fields:
                f.velocity_per_displacement.value = self.c_vel
                f.one_minus_alpha_f.value = 1 - s.alpha_f
            self._field_constants = (self.c_vel, s.alpha_f)
        scale_sq = 0.0
        if fe is not None:
            self.op = self.cache.get(dt)
            scale_sq = self._predictor_residual(state, dt)
            self._condense()
        z0, zd0, zdd0 = state.z, state.zd, state.zdd
        self.rigid_force_ext = rigid.external_force_N(self.t_mid)
        self._inertia_old = self._mass_old * zdd0
        self._rigid_diagonal_now = None
        # the predictor, the force scale |F|^2 + |m a_n|^2 (+ brakes) and the round-off bound's rigid inertia
        # m ((1 - alpha_m) a_hat + alpha_m a_n), a_hat = acceleration(0, 0, v_n, a_n), in one pass
        z1, inertia_sq, rigid_squares = np.empty((3, z0.size))
        rigid_step_start(z0, zd0, zdd0, rigid.mass_diagonal, self.rigid_force_ext, self._factors, s.alpha_m, z1,
                         inertia_sq, rigid_squares)
        if self._braked:
            rigid_squares += rigid.brake_force_N(zd0) ** 2
        rigid_scale_sq = float(np.sum(rigid_squares))
        self._force_scale = math.sqrt(scale_sq + rigid_scale_sq)
        # Below ~eps |terms| the residual is round-off: never ask for less. The rigid inertia is
        # formed from z / (beta dt^2)-sized terms; the FE terms are physical forces (see above).
        roundoff_sq = scale_sq + float(np.sum(inertia_sq))
        self._roundoff_force = 10 * _EPS * math.sqrt(roundoff_sq)
        rigid.apply_prescribed(self.t1, z1)
        self._initial_guess(z1 - z0)

    def _predictor_residual(self, state: TransientState, dt: float) -> float:
        """u_pred and r0 = residual of the FE equations at u_pred (three mat-vecs, module doc);
        returns the squared force scale |M a| ^2 + |C v| ^2 + |K u| ^2 + |F| ^2 of the tolerance.
        The Dirichlet change delta is zero off the constrained DOFs, so the mat-vec arguments are
        formed there without it (the same numbers, fewer passes over the arrays)."""
        s, fe, n = self.scheme, self.fe, self.n_fe
        u0, v0, a0 = state.u[:n], state.v[:n], state.a[:n]
        bc = fe.bc_local_owned
        predictor = self._u_pred
        pred = predictor.array_w
        taylor_bc = np.empty(bc.size)
        taylor_predictor(u0, v0, a0, dt, pred, bc, taylor_bc)
        fe.apply_dirichlet(self.t1, predictor)     # in place: ``pred`` views the same values
        r0, y = self._r0, self._tmp2
        fe.load_N(self.t_mid, r0)
        scale_sq = r0.norm() ** 2
        r0.scale(-1.0)
        x_M, x_K, x_C = self._matvec_arguments
        predictor_arguments(pred, u0, v0, a0, dt, bc, taylor_bc, (1 - s.alpha_m) * self.c_acc, self.c_vel,
                            1 - s.alpha_f, x_M.array_w, x_K.array_w, x_C.array_w)
        residual = r0.array_w
        for matrix, x in ((fe.M, x_M), (fe.K, x_K), (fe.C, x_C)):
            if matrix is None:
                continue
            matrix.mult(x, y)
            scale_sq += y.norm() ** 2
            residual += y.array_r       # r0.axpy(1.0, y), in numpy: the same sums, ~2x faster at this size
        residual[bc] = 0.0              # fe.zero_constrained(r0)
        del residual                    # (restores the array: r0's state changes)
        return scale_sq

    def _condense(self) -> None:
        """w = -K_eff^-1 r0: the FE solution without contact forces, and u_pred + w on every local DOF
        (owned and ghost): the end-of-step displacement at g = 0, from which the contact iterates
        differ by -G g."""
        self.op.solve(self._r0, self._w)      # -w
        u1 = petsc_vector(self._u1)
        np.subtract(self._u_pred.array_r, self._w.array_r, out=u1.array_w)     # u_pred + w
        self._u1.x.scatter_forward()
        self._u1_free = self._u1.x.array.copy()
        self._u1_is_free = True
        # the fields at g = 0 where the contact forms read them; the accepted iterate is formed on every
        # DOF (_evaluate_everywhere), so nothing reads the others before
        if self._rows_layout is None or not self._fields_formed:
            self._fe_fields(None)
        else:
            self._fe_fields(self._rows_layout.local)
        self._fe_key = np.zeros(self.contact_global.size).tobytes()

    def _contact_block(self) -> np.ndarray:
        """G_SS = E^T K_eff^-1 E of the current operator (s x s, every rank), formed once per dt."""
        if self.fe is None:
            return np.zeros((0, 0))
        return self.op.contact_block

    def _initial_guess(self, dz: np.ndarray) -> None:
        """g = 0 (no contact force), dz = rigid predictor increment."""
        X = self.X.array
        X[:] = 0.0
        if self.m_local:
            # The rigid unknowns are the increments z_{n+1} - z_n: absolute positions divided by
            # beta dt^2 would drown the accelerations in round-off at small dt.
            X[self.contact_global.size:] = dz

    def _split(self, x: np.ndarray):
        """(du owned entries, or None: the condensed iterate, du = w - G g with g in ``self._g``; dz
        on every rank; a key equal for equal du or None) of the iterate ``x`` (local array of the
        unknown (g, dz))."""
        self._unknown = unknown = self._replicated(x)
        s_count = self.contact_global.size
        self._g = g = unknown[:s_count]
        return None, unknown[s_count:], g.tobytes()

    def _evaluate(self, X: PETSc.Vec, everywhere: bool = False) -> bool:
        """Set u_{n+1}, z_{n+1} and every derived (mid-point) quantity from the iterate X.

        SNES asks for the Jacobian at the point whose residual it has just evaluated, and the
        accepted state is the last evaluated point: skip the re-evaluation then (the decision is
        global, since the evaluation is collective). While Newton iterates, the FE fields are
        updated at the DOFs the contact forms read only (``_evaluation_dofs``); ``everywhere`` (the
        accepted iterate, diagnostics) updates every DOF. Returns whether it evaluated (False: X is the last
        iterate evaluated)."""
        x = X.array_r
        # the same iterate, bit for bit (a cheaper test than array_equal on these few entries)
        same = self._evaluated is not None and self._evaluated_bytes == x.tobytes()
        if self.comm.size > 1:
            same = self.comm.allreduce(same, op=MPI.LAND)
        if same:
            if everywhere:
                self._evaluate_everywhere()
            return False
        self._evaluated = np.array(x)
        self._evaluated_bytes = self._evaluated.tobytes()
        du, dz, fe_key = self._split(x)
        st = self.state0
        # Iterates that differ only in the rigid increments (the contact-free path) share the FE
        # fields: keep them (the key is replicated, so every rank decides alike).
        same_fe = fe_key is not None and fe_key == self._fe_key and (self._fe_full or not everywhere)
        self._fe_key = fe_key
        if self.fe is not None and not same_fe:
            if du is None:
                self._condensed_fields(self._g, everywhere)
            else:
                petsc_vector(self._u1).array_w[:] = self._u_pred.array_r + du
                self._u1_is_free = False
                self._u1.x.scatter_forward()
                self._fe_fields(None)
        self.z1 = z1 = st.z + dz
        rigid = np.empty((4, z1.size))
        increment_kinematics(dz, z1, st.z, st.zd, st.zdd, self._factors, rigid[0], rigid[1], rigid[2], rigid[3])
        self.zdd1, self.zd1, self.z_mid, self.zd_mid = rigid
        self.iterate_version += 1
        self.rigid_version += 1
        for c in self.interactions:
            c.move_to_iterate(self)
        return True

    def rigid_mid_values(self) -> tuple[list, list]:
        """(z_mid, zd_mid) as lists of floats, formed once per rigid iterate (``rigid_version``): the rigid
        links and node contacts read a few of them, cheaper as floats than as numpy calls."""
        if self._rigid_values_version != self.rigid_version:
            self._rigid_values = (self.z_mid.tolist(), self.zd_mid.tolist())
            self._rigid_values_version = self.rigid_version
        return self._rigid_values

    def _evaluate_everywhere(self) -> None:
        """The last evaluated iterate (the accepted one) on every FE DOF: the new state, the probes and
        the field output read it."""
        if self.fe is not None and not self._fe_full:
            self._condensed_fields(self._g, everywhere=True)

    def _condensed_fields(self, g: np.ndarray, everywhere: bool) -> None:
        """u_{n+1} = u_pred + w - G g and the derived fields: at the evaluation DOFs only while Newton
        iterates (their rows of G), at every DOF for the accepted iterate."""
        nonzero = np.flatnonzero(g)
        rows = self.op.rows
        if everywhere or rows is None:
            u1 = petsc_vector(self._u1)
            if not nonzero.size:
                if not self._u1_is_free:        # else it holds u_pred + w already
                    self._u1.x.array[:] = self._u1_free
                    self._u1_is_free = True
            else:
                self._u1_is_free = False
                values = u1.array_w
                values[:] = self._u1_free[:self.n_fe]
                if self.op.columns_t is not None:
                    subtract_rows(values, self.op.columns_t, nonzero, g[nonzero])
                else:
                    self._tmp.set(0.0)
                    local = slice(self._S_offset, self._S_offset + self.contact_local.size)
                    self._tmp.array_w[self.contact_local] = g[local]
                    self.op.solve(self._tmp, self._tmp2)
                    values -= self._tmp2.array_r
                self._u1.x.scatter_forward()
            self._fe_fields(None)
            return
        at = self._rows_layout.local
        u1 = self._u1.x.array
        u1[at] = self._u1_free[at]
        if nonzero.size:
            u1[at] -= rows[:, nonzero] @ g[nonzero]
            self._u1_is_free = False
        self._fe_fields(at)

    def _fe_fields(self, at: np.ndarray | None) -> None:
        """a_{n+1}, v_{n+1} and the mid-point fields from u_{n+1} (in ``_u1``), at the local DOFs
        ``at`` or (None) at every DOF."""
        st = self.state0
        u1 = self._u1.x.array
        self.iterate_version += 1
        if at is None:
            if self.fields or self._rows_layout is None:
                step_kinematics(u1, st.u, st.v, st.a, self._factors, self.a1, self.v1, self.u_mid, self.v_mid)
            else:
                # no shared fields: the mid-points are read at the evaluation DOFs only (a node contact's), so form
                # them there; a_{n+1}, v_{n+1} (the new state) everywhere
                step_rates(u1, st.u, st.v, st.a, self._factors, self.a1, self.v1)
                step_kinematics_at(self._rows_layout.local, u1, st.u, st.v, st.a, self._factors, self.a1, self.v1,
                                   self.u_mid, self.v_mid)
            for f in self.fields:
                f.u_mid.x.array[:] = self.u_mid
                f.v_mid.x.array[:] = self.v_mid
            self._fe_full = self._fields_formed = True
            return
        step_kinematics_at(at, u1, st.u, st.v, st.a, self._factors, self.a1, self.v1, self.u_mid, self.v_mid)
        for f in self.fields:
            f.u_mid.x.array[at] = self.u_mid[at]
            f.v_mid.x.array[at] = self.v_mid[at]
        self._fe_full = False

    def _new_state(self) -> TransientState:
        if self.fe is not None:
            u, v, a = self._u1.x.array.copy(), self.v1.copy(), self.a1.copy()
        else:
            u = v = a = np.zeros(0)
        return TransientState(self.t1, u, v, a, self.z1.copy(), self.zd1.copy(), self.zdd1.copy())

    # ------------------------------------------------------------- residual
    def _contact_terms(self, r: PETSc.Vec | None) -> tuple[dict, np.ndarray, np.ndarray]:
        """Contact forces at the evaluated iterate: (forces by name, the FE contact residual at the
        contact DOFs rc_S (all ranks' entries), the rigid residual r_z). With ``r`` (an FE vector
        holding the rest of the FE residual) the contact residual is also added to it."""
        forces = {}
        # m (1 - alpha_m) zdd_{n+1} + m alpha_m zdd_n - F_ext
        r_z = self._mass_new * self.zdd1
        r_z += self._inertia_old
        r_z -= self.rigid_force_ext
        if self._braked:
            # brakes: a load -c omega at the generalised mid-point, like every other force of the step
            r_z -= self.rigid.brake_force_N(self.zd_mid)
        rc_S = np.zeros(self.contact_global.size)
        for c in self.interactions:
            forces[c.name] = c.add_residual(self, rc_S, r_z, r)
        # Forces at this iterate (reported without re-assembly if it is the converged one); a
        # surface contact's rc.dot is collective, so "any force" is the same on every rank.
        self._forces = forces
        self._forces_at = self._evaluated
        active = False
        for c in self._fe_contacts:
            if (forces[c.name] != 0.0).any():
                active = True
                break
        self._fe_contact_active = active
        r_z[self._fixed_axes] = 0.0
        return forces, rc_S, r_z

    def _residual_callback(self, snes, X, R) -> None:
        evaluated = self._evaluate(X)
        if snes is not None and not evaluated and self._residual_in_R and R.handle == self.R.handle:
            # SNES' first residual, at the iterate the contact-free step left in X and whose residual it left in R
            self._residual_in_R = False
            return
        _, rc_S, r_z = self._contact_terms(None)
        out = R.array   # on every rank: write access bumps the Vec state, so no rank reuses a cached norm
        if self.comm.rank == 0:
            s_count = self.contact_global.size
            out[:s_count] = rc_S - self._unknown[:s_count]
            out[s_count:] = r_z
        self._residual_in_R = snes is None and R.handle == self.R.handle

    def _rigid_block(self, Kzz: np.ndarray) -> np.ndarray:
        """Add the rigid-rigid interactions to the rigid block ``Kzz`` and put identity
        rows/columns on the prescribed axes."""
        empty = np.zeros((0, 0))
        for c in self._rigid_links:
            c.add_tangent(self, empty, empty, empty, Kzz)
        fixed = self._fixed_axes
        Kzz[fixed, :] = 0.0
        Kzz[:, fixed] = 0.0
        Kzz[fixed, fixed] = 1.0
        return Kzz

    def _replicated(self, x: np.ndarray) -> np.ndarray:
        """The unknown (held by rank 0) on every rank."""
        if self.comm.size == 1:
            return np.array(x)
        return self.comm.bcast(np.array(x) if self.comm.rank == 0 else None, root=0)

    def _gather_S(self, local: np.ndarray) -> np.ndarray:
        """Values at all contact DOFs (every rank's owned ones, in contact_global order)."""
        if self.comm.size == 1:
            return local[self.contact_local]
        return np.concatenate(self.comm.allgather(local[self.contact_local]))

    def _gather_rows(self, local_rows: np.ndarray) -> np.ndarray:
        """Stack per-rank row blocks (each rank's contact rows) into the full s x k array."""
        if self.comm.size == 1:
            return local_rows
        return np.vstack(self.comm.allgather(local_rows))

    # ------------------------------------------------------------- Jacobian
    def _contact_tangents(self):
        """(Kss, B, L, Kzz) at the evaluated iterate: d rc_S / d u_S (sparse, :class:`ContactTangent`),
        d rc_S / d z, d r_z / d u_S, d r_z / d z (prescribed rigid axes eliminated)."""
        s_count, m = self.contact_global.size, self.m
        Kss = ContactTangent(s_count)
        B = np.zeros((s_count, m))
        L = np.zeros((m, s_count))
        Kzz = np.diag(self._rigid_diagonal())
        for c in self._fe_contacts:
            c.add_tangent(self, Kss, B, L, Kzz)
        Kzz = self._rigid_block(Kzz)
        fixed = self._fixed_axes
        L[fixed, :] = 0.0
        B[:, fixed] = 0.0
        return Kss, B, L, Kzz

    def contact_tangent_block(self, A: PETSc.Mat) -> scipy.sparse.csr_matrix:
        """The rows and columns of the contact DOFs of an FE matrix ``A`` (an interaction's tangent,
        whose sparsity pattern does not change) as a sparse s x s matrix on every rank, in
        contact_global order (PETSc's submatrix extraction, its storage reused)."""
        s_count = self.contact_global.size
        subs = self.__dict__.setdefault("_tangent_submatrices", {})
        key = A.handle
        if key not in subs:
            owned = (self.contact_local + self.fe.first_global).astype(PETSc.IntType)
            index = PETSc.IS().createGeneral(owned, comm=self.comm)
            subs[key] = (index, A.createSubMatrix(index, index))
        else:
            index, sub = subs[key]
            A.createSubMatrix(index, index, submat=sub)
        indptr, indices, values = subs[key][1].getValuesCSR()
        if self.comm.size == 1:
            return scipy.sparse.csr_matrix((values, indices, indptr), shape=(s_count, s_count))
        parts = self.comm.allgather((indptr, indices, values))
        return scipy.sparse.vstack([scipy.sparse.csr_matrix((v, i, p), shape=(p.size - 1, s_count))
                                    for p, i, v in parts], format="csr")

    def _jacobian_callback(self, snes, X, J, P) -> None:
        self._evaluate(X)
        self._set_jacobian(*self._contact_tangents())

    def _set_jacobian(self, Kss, B, L, Kzz) -> None:
        """Factorise the condensed Newton matrix on the DOFs its tangents make active
        (:class:`app.transient.active_set.CondensedJacobian`), on rank 0, which holds the unknown."""
        if self.comm.rank != 0:
            return
        if isinstance(Kss, ContactTangent) and Kss.empty and not B.any() and not L.any():
            # no FE contact carries force: the factorised Kzz, kept while it recurs (same dt and rigid links)
            key = Kzz.tobytes()
            jacobian = self._rigid_jacobians.get(key)
            if jacobian is None:
                if len(self._rigid_jacobians) >= 16:
                    self._rigid_jacobians.clear()
                jacobian = self._rigid_jacobians[key] = RigidJacobian(self.contact_global.size, Kzz)
            self._jacobian = jacobian
            return
        previous = self._jacobian
        self._jacobian = CondensedJacobian(self._contact_block(), Kss, B, L, Kzz, active_only=self.active_set)
        self.jacobians += 1
        self.active_dofs += self._jacobian.active_count
        active = self._jacobian.active
        if previous is not None and self._jacobian_step == self._step_count and (
                previous.active.shape != active.shape or (previous.active != active).any()):
            self.active_set_changes += 1
        self._jacobian_step = self._step_count

    def apply_inverse(self, x: np.ndarray, y: np.ndarray) -> None:
        """y = J^-1 x for local arrays of the unknown (rank 0 holds it all)."""
        if x.size:
            y[:] = self._jacobian.solve(x)
            if self._jacobian.inactive.size and x[self._jacobian.inactive].any():
                self.opened_updates += 1

    def apply_jacobian(self, x: np.ndarray, y: np.ndarray) -> None:
        """y = J x for local arrays of the unknown."""
        if x.size:
            y[:] = self._jacobian.apply(x)

    def consistent_rigid_acceleration(self, state: TransientState) -> TransientState:
        """``state`` with the free rigid accelerations in equilibrium with the external loads and the
        rigid-rigid interactions at ``state`` (a start inside a closed link, e.g. a disc resting on
        a plane with friction: an inconsistent a_0 leaves a lasting velocity offset of order
        dt |a_0 error| / 2 in the trapezoidal rule)."""
        rigid = self.rigid
        self.z_mid, self.zd_mid = state.z, state.zd
        self.iterate_version += 1
        self.rigid_version += 1
        r_z = -rigid.external_force_N(state.t) - rigid.brake_force_N(state.zd)
        for c in self.interactions:
            if not c.fe_coupled:
                c.add_residual(self, np.zeros(0), r_z, None)
        self._evaluated = self._fe_key = None       # z_mid no longer belongs to an iterate
        zdd = state.zdd.copy()
        free = rigid.free_mask & (rigid.mass_diagonal > 0)
        zdd[free] = -r_z[free] / rigid.mass_diagonal[free]
        return TransientState(state.t, state.u, state.v, state.a, state.z, state.zd, zdd)

    # ------------------------------------------------------------ checks
    def full_residual_norm(self) -> float:
        """|r0 + A du + E rc| of the FE equations plus the rigid residual at the evaluated iterate:
        the residual of the uncondensed system (one extra mat-vec; for tests and diagnostics)."""
        self._evaluated = self._fe_key = None   # the shared mid-point fields may hold other values by now
        self._evaluate(self.X, everywhere=True)
        r = self._r
        self._du.array_w[:] = petsc_vector(self._u1).array_r - self._u_pred.array_r
        self.op.full.mult(self._du, r)
        r.axpy(1.0, self._r0)
        _, _, r_z = self._contact_terms(r)
        self.fe.zero_constrained(r)
        return float(np.sqrt(r.norm() ** 2 + float(np.sum(r_z**2))))

    # ------------------------------------------------------------ reporting
    def show_state(self, state: TransientState) -> None:
        """Make ``solution_vector`` show the displacement of ``state`` (e.g. the initial state)."""
        if self.fe is not None:
            self._u1.x.array[:] = state.u
            self._u1_is_free = False

    @property
    def solution_vector(self) -> PETSc.Vec:
        """u_{n+1} of the last solved step (FE space layout), for probes and field output."""
        return petsc_vector(self._u1)

    @property
    def solution_array(self) -> np.ndarray:
        """u_{n+1} of the last solved step as the local array (owned + ghosts, scattered)."""
        return self._u1.x.array

    def contact_forces_N(self) -> dict[str, np.ndarray]:
        """Force on the rigid body (surface contacts) or on the upper body (point contacts) at the
        mid-point of the last evaluated iterate, as gdim vectors [N]."""
        if getattr(self, "_forces_at", None) is self._evaluated and self._evaluated is not None:
            return dict(self._forces)
        forces, _, _ = self._contact_terms(None)
        return dict(forces)

    @property
    def contact_names(self) -> list[str]:
        """Contact names in the order of ``ContactStatus.closed``."""
        return [c.name for c in self.interactions]

    def destroy(self) -> None:
        if self.cache is not None:
            self.cache.destroy()
        for index, sub in getattr(self, "_tangent_submatrices", {}).values():
            index.destroy()
            sub.destroy()
        for obj in (self.snes, self.J, self.X, self.R, self._step_vector):
            obj.destroy()


class _JacobianShell:
    def __init__(self, system: CoupledSystem):
        self.system = system

    def mult(self, mat, x, y):
        self.system.apply_jacobian(x.array_r, y.array)


class _ShellInverse:
    def __init__(self, system: CoupledSystem):
        self.system = system

    def apply(self, pc, x, y):
        self.system.apply_inverse(x.array_r, y.array)
