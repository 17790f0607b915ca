"""One implicit step of FE + rigid bodies + penalty contact, solved by PETSc SNES with a bordered
linear solve.

Unknowns of a step: the FE displacement u_{n+1} (owned DOFs) and the rigid positions z_{n+1}
(held by rank 0), packed in one PETSc Vec. The Newton matrix is

    [ A + E Kss E^T    E B ] [du]   [r_u]
    [ L E^T            Kzz ] [dz] = [r_z]

with A = K_eff (constant for a given dt, factorised once by :class:`EffectiveOperator`), E the
unit columns of the s contact DOFs, Kss the s x s contact tangent, B/L the contact coupling to
the rigid DOFs and Kzz the rigid block (mass, Kelvin-Voigt links, contact). With w = A^-1 r_u and
G = A^-1 E (precomputed per dt), du = w - G y where the (s + m) dense system

    [ I + Kss G_S   -B  ] [y ]   [ Kss w_S     ]
    [ -L G_S        Kzz ] [dz] = [ r_z - L w_S ]

gives the contact correction y and dz (G_S = E^T G). The exact Newton step thus costs one
back-substitution with the constant factorisation plus an n x s product: contact never triggers
a refactorisation. SNES (prefix ``transient_``) drives the iteration with a line search through a
shell preconditioner applying this inverse and a shell matrix applying J.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from mpi4py import MPI
from petsc4py import PETSc

from app.transient.contact import NodeContact, PointContact, SurfaceContact
from app.transient.fe import EffectiveOperatorCache, LinearFE
from app.transient.rigid import RigidSet
from app.transient.state import TransientState
from app.transient.threads import limit_blas_threads
from forms.newmark import (
    TimeScheme,
    acceleration,
    acceleration_per_displacement,
    midpoint,
    velocity,
    velocity_per_displacement,
)

SNES_PREFIX = "transient_"
SNES_DEFAULTS = {
    "snes_type": "newtonls",
    # Semi-smooth Newton: the penalty residual is piecewise linear with an exact tangent, so full
    # steps converge in a few iterations once the active set settles; a backtracking search on
    # this non-smooth residual only costs Jacobian products. Failure -> cut-back (control.py).
    "snes_linesearch_type": "basic",
    "snes_rtol": 1e-10,
    "snes_stol": 1e-14,
    "snes_max_it": 20,
}


class CoupledSystem:
    """Residual, Jacobian and bordered solve of one generalized-alpha step."""

    def __init__(self, comm, scheme: TimeScheme, fe: LinearFE | None, rigid: RigidSet,
                 surface_contacts: list[SurfaceContact] = (), point_contacts: list[PointContact] = (),
                 relative_force_tolerance: float = 1e-10, node_contacts: list[NodeContact] = ()):
        limit_blas_threads()    # MPI ranks are the parallelism (see app.transient.threads)
        self.comm, self.scheme, self.fe, self.rigid = comm, scheme, fe, rigid
        self.surface_contacts = list(surface_contacts)
        self.point_contacts = list(point_contacts)
        self.node_contacts = list(node_contacts)
        self.relative_force_tolerance = relative_force_tolerance
        for c in self.surface_contacts:
            if c.body not in rigid.index:
                raise ValueError(f"contact {c.name!r} names unknown rigid body {c.body!r}")
            c.set_body_reference(rigid.bodies[rigid.index[c.body]].position_m)
        for c in self.node_contacts:
            if c.body not in rigid.index:
                raise ValueError(f"contact {c.name!r} names unknown rigid body {c.body!r}")
            c.set_body_reference(rigid.bodies[rigid.index[c.body]].position_m)
        for c in self.point_contacts:
            for name in (c.lower, c.upper):
                if name not in rigid.index:
                    raise ValueError(f"contact {c.name!r} names unknown rigid body {name!r}")
        self.n_fe = fe.n_owned if fe is not None else 0
        self.m = rigid.size
        self.m_local = self.m if comm.rank == 0 else 0
        self._setup_contact_dofs()
        self.cache = EffectiveOperatorCache(fe, scheme, self.contact_global) if fe is not None else None
        self.fields = list({id(c.fields): c.fields for c in self.surface_contacts}.values())
        if fe is not None:
            from dolfinx import fem

            self._u1 = fem.Function(fe.space)
            self.translations = fe.translation_vectors()
            self._b = fe.new_vector()
            self._r = fe.new_vector()
            self._tmp = fe.new_vector()
            self._tmp2 = fe.new_vector()
            self._u_pred = fe.new_vector()
            self._r0 = fe.new_vector()
            self._du = fe.new_vector()
        self._setup_snes()
        self.last_iterations = 0
        self.total_iterations = 0
        self.linear_steps = 0           # steps solved by the contact-free fast path
        self._evaluated = None

    # ----------------------------------------------------------------- setup
    def _setup_contact_dofs(self) -> None:
        fe_contacts = self.surface_contacts + self.node_contacts
        if self.fe is None or not fe_contacts:
            self.contact_local = np.zeros(0, dtype=np.int32)
            self.contact_global = np.zeros(0, dtype=PETSc.IntType)
            self.translation_S = np.zeros((0, self.rigid.gdim))
            self._S_offset = 0
            self._node_S = []
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
        position = {int(g): i for i, g in enumerate(self.contact_global)}
        self._node_S = []
        for c in self.node_contacts:
            mine = [(int(d + self.fe.first_global), int(k)) for d, k in zip(c.local_dofs, c.dof_axes)]
            pairs = self.comm.bcast(mine, root=c.owner)
            self._node_S.append((np.array([position[g] for g, _ in pairs], dtype=int),
                                 np.array([k for _, k in pairs], dtype=int)))

    def _setup_snes(self) -> None:
        n_local = self.n_fe + self.m_local
        sizes = (n_local, PETSc.DECIDE)
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
        pc.setPythonContext(_BorderedInverse(self))
        snes.setFromOptions()
        ksp.setType("preonly")
        self.snes = snes

    # ------------------------------------------------------------- one step
    def solve_step(self, state: TransientState, dt: float) -> tuple[int, TransientState | None]:
        """Try one step from ``state``. Returns (SNES converged reason, new state or None)."""
        self._begin_step(state, dt)
        atol = self.relative_force_tolerance * self._force_scale + self._roundoff_force + 1e-300
        try:
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
        # Forces now, at the converged mid-point fields: other users of the shared fields (the
        # contact monitor, energy account) overwrite them with end-of-step values afterwards.
        self.last_forces_N = self.contact_forces_N()
        return reason, self._new_state()

    def _contact_free_step(self, atol: float):
        """A step in which no FE contact (surface, node) carries force, neither at the predictor nor
        at the result, needs no FE contact tangent: take one Newton step with zero FE contact blocks
        (the rigid block keeps mass and Kelvin-Voigt links) without SNES and its Python callbacks,
        check the residual with the same absolute/relative test as SNES, and return the converged
        reason; None (X left at a valid guess) hands the step to SNES. Same arithmetic as SNES'
        first iteration (basic line search), so the result does not depend on the path; if a
        rigid-rigid link opens or closes within the step, the residual test fails and SNES
        iterates."""
        X, R = self.X, self.R
        self._residual_callback(None, X, R)
        if self._fe_contact_active:
            return None
        norm0 = R.norm()
        if not np.isfinite(norm0):
            raise FloatingPointError("non-finite residual")
        if norm0 <= atol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        self._set_contact_free_jacobian()
        Y = self._step_vector
        self.apply_inverse(R.array_r, Y.array)
        X.axpy(-1.0, Y)
        self._residual_callback(None, X, R)
        norm1 = R.norm()
        if self._fe_contact_active or not np.isfinite(norm1):
            return None
        rtol = SNES_DEFAULTS["snes_rtol"]
        if norm1 <= atol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        if norm1 <= rtol * norm0:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_RELATIVE
        return None

    def _set_contact_free_jacobian(self) -> None:
        """The bordered-solve data of a Jacobian with every FE contact block zero, as
        ``_jacobian_callback`` builds it when no FE contact is active."""
        s_count, m = self.contact_global.size, self.m
        Kzz = self._rigid_block(np.diag((1 - self.scheme.alpha_m) * self.c_acc * self.rigid.mass_diagonal))
        self._Kss = np.zeros((s_count, s_count))
        self._B = np.zeros((s_count, m))
        self._L = np.zeros((m, s_count))
        self._Kzz = Kzz
        Z = np.block([[np.eye(s_count), np.zeros((s_count, m))], [np.zeros((m, s_count)), Kzz]])
        self._Z_lu = scipy.linalg.lu_factor(Z, check_finite=True) if Z.size else None

    def _begin_step(self, state: TransientState, dt: float) -> None:
        s, fe, rigid = self.scheme, self.fe, self.rigid
        self.state0, self.dt = state, dt
        self._evaluated = None
        self.t1 = state.t + dt
        self.t_mid = midpoint(self.t1, state.t, s.alpha_f)
        self.c_acc = acceleration_per_displacement(dt, s)
        self.c_vel = velocity_per_displacement(dt, s)
        for f in self.fields:
            f.velocity_per_displacement.value = self.c_vel
            f.one_minus_alpha_f.value = 1 - s.alpha_f
        X = self.X.array
        scale_sq = 0.0
        if fe is not None:
            self.op = self.cache.get(dt)
            u0, v0, a0 = state.u, state.v, state.a
            a_hat = acceleration(0.0, u0, v0, a0, dt, s)
            v_hat = velocity(a_hat, v0, a0, dt, s)
            n = self.n_fe
            b, tmp, tmp2 = self._b, self._tmp, self._tmp2
            # b = F(t_mid) - M a_const - C v_const - alpha_f K u_n, with every product formed
            # once: K u_n, M a_n and F also give the force scale of the absolute tolerance
            # (physical forces only: b holds u_n / (beta dt^2)-sized terms).
            fe.load_N(self.t_mid, b)
            scale_sq += b.norm() ** 2
            tmp.array_w[:] = u0[:n]
            fe.K.mult(tmp, tmp2)
            scale_sq += tmp2.norm() ** 2
            if s.alpha_f:
                b.axpy(-s.alpha_f, tmp2)
            tmp.array_w[:] = a0[:n]
            fe.M.mult(tmp, tmp2)
            scale_sq += tmp2.norm() ** 2
            if s.alpha_m:
                b.axpy(-s.alpha_m, tmp2)
            tmp.array_w[:] = a_hat[:n]
            fe.M.mult(tmp, tmp2)
            b.axpy(-(1 - s.alpha_m), tmp2)
            if fe.C is not None:
                tmp.array_w[:] = ((1 - s.alpha_f) * v_hat + s.alpha_f * v0)[:n]
                fe.C.mult(tmp, tmp2)
                b.axpy(-1.0, tmp2)
            # The FE unknown is the correction du = u_{n+1} - u_pred to a predictor that already
            # carries the Dirichlet values of t_{n+1}. The residual is then r0 + K_eff du + contact
            # with r0 = K_eff u_pred - b evaluated once: K_eff u_{n+1} - b itself cancels terms of
            # size M u / (beta dt^2), and its round-off (~1e-10 relative) used to stall Newton at
            # the tolerance and trigger line-search failures and cut-backs.
            predictor = self._u_pred
            predictor.array_w[:] = (u0 + dt * v0 + 0.5 * dt * dt * a0)[:n]
            fe.apply_dirichlet(self.t1, predictor)
            self.op.full.mult(predictor, self._r0)
            self._r0.axpy(-1.0, b)
            X[:n] = 0.0
        z0, zd0, zdd0 = state.z, state.zd, state.zdd
        self.zdd_hat = acceleration(0.0, 0.0, zd0, zdd0, dt, s)
        self.zd_hat = velocity(self.zdd_hat, zd0, zdd0, dt, s)
        self.rigid_force_ext = rigid.external_force_N(self.t_mid)
        self.rigid_inertia_const = rigid.mass_diagonal * ((1 - s.alpha_m) * self.zdd_hat + s.alpha_m * zdd0)
        rigid_scale_sq = float(np.sum(self.rigid_force_ext**2 + (rigid.mass_diagonal * zdd0) ** 2))
        self._force_scale = float(np.sqrt(scale_sq + rigid_scale_sq))
        # Below ~eps |b| the residual is round-off: never ask for less.
        roundoff_sq = (b.norm() ** 2 if fe is not None else 0.0) + float(np.sum(self.rigid_inertia_const**2))
        self._roundoff_force = 10 * np.finfo(float).eps * float(np.sqrt(roundoff_sq))
        z1 = z0 + dt * zd0 + 0.5 * dt * dt * zdd0
        rigid.apply_prescribed(self.t1, z1)
        if self.m_local:
            # The rigid unknowns are the increments z_{n+1} - z_n: absolute positions divided by
            # beta dt^2 would drown the accelerations in round-off at small dt.
            X[self.n_fe:] = z1 - z0

    def _evaluate(self, X: PETSc.Vec) -> None:
        """Set u_{n+1}, z_{n+1} and every derived (mid-point) quantity from the iterate X.

        SNES asks for the Jacobian at the point whose residual it has just evaluated, and the
        accepted state is the last evaluated point: skip the re-evaluation then (the decision is
        global, since the evaluation is collective)."""
        x = X.array_r
        same = self._evaluated is not None and self._evaluated.shape == x.shape and np.array_equal(self._evaluated, x)
        if self.comm.size > 1:
            same = self.comm.allreduce(same, op=MPI.LAND)
        if same:
            return
        self._evaluated = np.array(x)
        s, st, dt = self.scheme, self.state0, self.dt
        if self.fe is not None:
            self._u1.vector.array_w[:] = self._u_pred.array_r + x[: self.n_fe]
            self._u1.x.scatter_forward()
            u1 = self._u1.x.array
            self.a1 = acceleration(u1, st.u, st.v, st.a, dt, s)
            self.v1 = velocity(self.a1, st.v, st.a, dt, s)
            self.u_mid = midpoint(u1, st.u, s.alpha_f)
            self.v_mid = midpoint(self.v1, st.v, s.alpha_f)
            for f in self.fields:
                f.u_mid.x.array[:] = self.u_mid
                f.v_mid.x.array[:] = self.v_mid
        dz = self._rigid_part(x)
        z1 = st.z + dz
        self.z1 = z1
        self.zdd1 = acceleration(dz, 0.0, st.zd, st.zdd, dt, s)
        self.zd1 = velocity(self.zdd1, st.zd, st.zdd, dt, s)
        self.z_mid = midpoint(z1, st.z, s.alpha_f)
        self.zd_mid = midpoint(self.zd1, st.zd, s.alpha_f)
        for c in self.surface_contacts:
            sl = self.rigid.dofs(c.body)
            c.set_body_state(self.z_mid[sl], self.zd_mid[sl])

    def _new_state(self) -> TransientState:
        if self.fe is not None:
            u, v, a = self._u1.x.array.copy(), self.v1.copy(), self.a1.copy()
        else:
            u = v = a = np.zeros(0)
        return TransientState(self.t1, u, v, a, self.z1.copy(), self.zd1.copy(), self.zdd1.copy())

    # ------------------------------------------------------------- residual
    def _residual_callback(self, snes, X, R) -> None:
        self._evaluate(X)
        forces = {}
        r_z = self.rigid.mass_diagonal * (1 - self.scheme.alpha_m) * self.zdd1
        r_z = r_z + self.rigid.mass_diagonal * self.scheme.alpha_m * self.state0.zdd - self.rigid_force_ext
        out = R.array
        if self.fe is not None:
            r, du = self._r, self._du
            x_fe = X.array_r[: self.n_fe]
            if x_fe.any():
                du.array_w[:] = x_fe
                self.op.full.mult(du, r)
                r.axpy(1.0, self._r0)
            else:                       # the first residual of a step is r0 (no mat-vec)
                self._r0.copy(r)
            for c in self.surface_contacts:
                rc = c.assemble_residual()
                r.axpy(1.0, rc)
                sl = self.rigid.dofs(c.body)
                forces[c.name] = np.array([rc.dot(tk) for tk in self.translations])
                r_z[sl] -= forces[c.name]
            for c in self.node_contacts:
                f, _, _ = self._node_force(c)
                if c.local_dofs.size:
                    r.array_w[c.local_dofs] -= f * c.normal[c.dof_axes]
                r_z[self.rigid.dofs(c.body)] += f * c.normal
                forces[c.name] = -f * c.normal
            self.fe.zero_constrained(r)
            out[: self.n_fe] = r.array_r
        for c in self.point_contacts:
            f, _, _ = self._point_force(c)
            r_z[self.rigid.dofs(c.upper)] -= f * c.normal
            r_z[self.rigid.dofs(c.lower)] += f * c.normal
            forces[c.name] = f * c.normal
        # Forces at this iterate (reported without re-assembly if it is the converged one); a
        # surface contact's rc.dot is collective, so "any force" is the same on every rank.
        self._forces = forces
        self._forces_at = self._evaluated
        fe_names = {c.name for c in self.surface_contacts + self.node_contacts}
        self._fe_contact_active = any(np.any(forces[n] != 0.0) for n in fe_names)
        r_z[~self.rigid.free_mask] = 0.0
        if self.m_local:
            out[self.n_fe:] = r_z

    def _node_force(self, c: NodeContact):
        sl = self.rigid.dofs(c.body)
        delta, rate = c.penetration(self.u_mid, self.v_mid, self.z_mid[sl], self.zd_mid[sl])
        return c.force(delta, rate)

    def _point_force(self, c: PointContact):
        lo, up = self.rigid.dofs(c.lower), self.rigid.dofs(c.upper)
        delta, rate = c.penetration(self.z_mid[lo], self.z_mid[up], self.zd_mid[lo], self.zd_mid[up])
        return c.force(delta, rate)

    def _rigid_block(self, Kzz: np.ndarray) -> np.ndarray:
        """Add the Kelvin-Voigt links between rigid bodies to the rigid block ``Kzz`` and put
        identity rows/columns on the prescribed axes."""
        one_minus_af = 1 - self.scheme.alpha_f
        for c in self.point_contacts:
            _, k_f, c_f = self._point_force(c)
            stiffness = one_minus_af * (k_f + c_f * self.c_vel) * np.outer(c.normal, c.normal)
            lo, up = self.rigid.dofs(c.lower), self.rigid.dofs(c.upper)
            Kzz[up, up] += stiffness
            Kzz[lo, lo] += stiffness
            Kzz[up, lo] -= stiffness
            Kzz[lo, up] -= stiffness
        fixed = ~self.rigid.free_mask
        Kzz[fixed, :] = 0.0
        Kzz[:, fixed] = 0.0
        Kzz[fixed, fixed] = 1.0
        return Kzz

    def _rigid_part(self, x: np.ndarray) -> np.ndarray:
        """The rigid entries of a packed local array (held by rank 0), on every rank."""
        if self.comm.size == 1:
            return np.array(x[self.n_fe:])
        return self.comm.bcast(np.array(x[self.n_fe:]) if self.comm.rank == 0 else None, root=0)

    def _gather_S(self, local: np.ndarray) -> np.ndarray:
        """Values at all contact DOFs (every rank's owned ones, in contact_global order)."""
        if self.comm.size == 1:
            return local[self.contact_local]
        return np.concatenate(self.comm.allgather(local[self.contact_local]))

    # ------------------------------------------------------------- Jacobian
    def _gather_rows(self, local_rows: np.ndarray) -> np.ndarray:
        """Stack per-rank row blocks (each rank's contact rows) into the full s x k array."""
        if self.comm.size == 1:
            return local_rows
        return np.vstack(self.comm.allgather(local_rows))

    def _jacobian_callback(self, snes, X, J, P) -> None:
        self._evaluate(X)
        s_count, m = self.contact_global.size, self.m
        Kss = np.zeros((s_count, s_count))
        B = np.zeros((s_count, m))
        L = np.zeros((m, s_count))
        Kzz = np.diag((1 - self.scheme.alpha_m) * self.c_acc * self.rigid.mass_diagonal)
        T = self.translation_S
        owned_rows = (self.contact_local + self.fe.first_global).astype(PETSc.IntType) if self.fe else None
        for c in self.surface_contacts:
            A = c.assemble_tangent()
            block = self._gather_rows(A.getValues(owned_rows, self.contact_global)
                                      .reshape(owned_rows.size, s_count))
            Kss += block
            sl = self.rigid.dofs(c.body)
            B[:, sl] -= block @ T
            L[sl, :] -= T.T @ block
            Kzz[sl, sl] += T.T @ block @ T
        one_minus_af = 1 - self.scheme.alpha_f
        for c, (S, axes) in zip(self.node_contacts, self._node_S):
            _, k_f, c_f = self._node_force(c)
            block = np.zeros((s_count, s_count))
            n_S = c.normal[axes]
            block[np.ix_(S, S)] = one_minus_af * (k_f + c_f * self.c_vel) * np.outer(n_S, n_S)
            Kss += block
            sl = self.rigid.dofs(c.body)
            B[:, sl] -= block @ T
            L[sl, :] -= T.T @ block
            Kzz[sl, sl] += T.T @ block @ T
        Kzz = self._rigid_block(Kzz)
        fixed = ~self.rigid.free_mask
        L[fixed, :] = 0.0
        B[:, fixed] = 0.0
        G_S = (self._gather_rows(self.op.columns[self.contact_local]) if self.fe is not None
               else np.zeros((0, 0)))
        Z = np.block([[np.eye(s_count) + Kss @ G_S, -B], [-L @ G_S, Kzz]])
        self._Kss, self._B, self._L, self._Kzz = Kss, B, L, Kzz
        self._Z_lu = scipy.linalg.lu_factor(Z, check_finite=True) if Z.size else None

    # ------------------------------------------------------- bordered solve
    def apply_inverse(self, x: np.ndarray, y: np.ndarray) -> None:
        """y = J^-1 x for local arrays of the packed vector."""
        n, s_count = self.n_fe, self.contact_global.size
        r_z = self._rigid_part(x)
        if self.fe is not None:
            self._tmp.array_w[:] = x[:n]
            self.op.solve(self._tmp, self._tmp2)
            w = self._tmp2.array_r.copy()
            w_S = self._gather_S(w) if s_count else np.zeros(0)
        else:
            w, w_S = np.zeros(0), np.zeros(0)
        if self._Z_lu is not None:
            rhs = np.concatenate([self._Kss @ w_S, r_z - self._L @ w_S])
            sol = scipy.linalg.lu_solve(self._Z_lu, rhs)
            y_contact, dz = sol[:s_count], sol[s_count:]
        else:
            y_contact, dz = np.zeros(0), np.zeros(0)
        if self.fe is not None:
            y[:n] = w - self.op.columns @ y_contact if s_count else w
        if self.m_local:
            y[n:] = dz

    def apply_jacobian(self, x: np.ndarray, y: np.ndarray) -> None:
        """y = J x for local arrays of the packed vector."""
        n, s_count = self.n_fe, self.contact_global.size
        x_z = self._rigid_part(x)
        if self.fe is not None:
            self._tmp.array_w[:] = x[:n]
            self.op.constrained.mult(self._tmp, self._tmp2)
            y_u = self._tmp2.array_r.copy()
            x_S = self._gather_S(x[:n]) if s_count else np.zeros(0)
            if s_count:
                local = slice(self._S_offset, self._S_offset + self.contact_local.size)
                y_u[self.contact_local] += (self._Kss @ x_S + self._B @ x_z)[local]
            y[:n] = y_u
        else:
            x_S = np.zeros(0)
        if self.m_local:
            y[n:] = self._L @ x_S + self._Kzz @ x_z

    # ------------------------------------------------------------ reporting
    def show_state(self, state: TransientState) -> None:
        """Make ``solution_vector`` show the displacement of ``state`` (e.g. the initial state)."""
        if self.fe is not None:
            self._u1.x.array[:] = state.u

    @property
    def solution_vector(self) -> PETSc.Vec:
        """u_{n+1} of the last solved step (FE space layout), for probes and field output."""
        return self._u1.vector

    @property
    def solution_array(self) -> np.ndarray:
        """u_{n+1} of the last solved step as the local array (owned + ghosts, scattered)."""
        return self._u1.x.array

    def contact_forces_N(self) -> dict[str, np.ndarray]:
        """Force on the rigid body (surface contacts) or on the upper body (point contacts) at the
        mid-point of the last evaluated iterate, as gdim vectors [N]."""
        if getattr(self, "_forces_at", None) is self._evaluated and self._evaluated is not None:
            return dict(self._forces)
        out = {}
        for c in self.surface_contacts:
            rc = c.assemble_residual()
            out[c.name] = np.array([rc.dot(tk) for tk in self.translations])
        for c in self.node_contacts:
            f, _, _ = self._node_force(c)
            out[c.name] = -f * c.normal
        for c in self.point_contacts:
            f, _, _ = self._point_force(c)
            out[c.name] = f * c.normal
        return out

    @property
    def contact_names(self) -> list[str]:
        """Contact names in the order of ``ContactStatus.closed``."""
        return [c.name for c in self.surface_contacts + self.node_contacts + self.point_contacts]

    def destroy(self) -> None:
        if self.cache is not None:
            self.cache.destroy()
        for obj in (self.snes, self.J, self.X, self.R, self._step_vector):
            obj.destroy()


class _JacobianShell:
    def __init__(self, system: CoupledSystem):
        self.system = system

    def mult(self, mat, x, y):
        self.system.apply_jacobian(x.array_r, y.array)


class _BorderedInverse:
    def __init__(self, system: CoupledSystem):
        self.system = system

    def apply(self, pc, x, y):
        self.system.apply_inverse(x.array_r, y.array)
