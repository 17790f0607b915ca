"""The coupled step without condensation: Newton on all FE + rigid unknowns, the reference for the
condensed step of app/transient/coupled.py.

piezodyn's transient step condenses the FE part onto the contact DOFs: Newton iterates on the
contact forces and rigid DOFs only, with the FE matrix factorised once per step size. This demo keeps
the same step (same residual, tangents, tolerances) as a Newton iteration on (du, dz), the FE
correction and the rigid increments; the Newton matrix

    [ A + E Kss E^T    E B ] [du]   [r_u]
    [ L E^T            Kzz ] [dz] = [r_z]

is applied by a bordered solve: with w = A^-1 r_u and G = A^-1 E, du = w - G y where the dense
(s + m) system [[I + Kss G_S, -B], [-L G_S, Kzz]] [y, dz] = [Kss w_S, r_z - L w_S] gives y, dz.
Every iteration thus costs a back-substitution and a mat-vec with A on top of the condensed
iteration's small work. The demo runs Saint-Venant's rod impact (demos/demo_rod_impact.py) both
ways: the same time steps and contact forces to the Newton tolerance (1e-10 of the force scale per
step; 1e-7 over the run). ``bench/bench_transient.py`` builds its naive loop on this class.

    python demos/demo_fullspace.py               # or: mpirun -n 2 python demos/demo_fullspace.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # runnable as ``python demos/<this file>``

import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402
from mpi4py import MPI  # noqa: E402

from app.transient.coupled import CoupledSystem  # noqa: E402
from app.transient.stepper import run_scene  # noqa: E402
from demos.demo_rod_impact import RodImpact, build_rod_impact, rod_step_sizes  # noqa: E402
from forms.newmark import TimeScheme  # noqa: E402

FORCE_RTOL = 1e-7


class FullSpaceSystem(CoupledSystem):
    """:class:`CoupledSystem` iterating on (du, dz) instead of the condensed (g, dz)."""

    def _unknowns_local(self) -> int:
        return self.n_fe + self.m_local

    def _condense(self) -> None:
        pass            # iterates on du itself: no contact-free solution needed

    def _initial_guess(self, dz: np.ndarray) -> None:
        X = self.X.array
        X[:] = 0.0
        if self.m_local:
            X[self.n_fe:] = dz

    def _split(self, x: np.ndarray):
        n = self.n_fe
        if self.comm.size == 1:
            dz = np.array(x[n:])
        else:
            dz = self.comm.bcast(np.array(x[n:]) if self.comm.rank == 0 else None, root=0)
        return (np.array(x[:n]) if self.fe is not None else None), dz, None

    def _residual_callback(self, snes, X, R) -> None:
        self._evaluate(X)
        out = R.array
        r = None
        if self.fe is not None:
            r, du = self._r, self._du
            x_fe = X.array_r[: self.n_fe]
            if x_fe.any():
                du.array_w[:] = x_fe
                self.op.full.mult(du, r)
                r.axpy(1.0, self._r0)
            else:
                self._r0.copy(r)
        _, _, r_z = self._contact_terms(r)
        if r is not None:
            self.fe.zero_constrained(r)
            out[: self.n_fe] = r.array_r
        if self.m_local:
            out[self.n_fe:] = r_z

    def _set_jacobian(self, Kss, B, L, Kzz) -> None:
        s_count = self.contact_global.size
        G_S = self._contact_block()
        Z = np.block([[np.eye(s_count) + Kss @ G_S, -B], [-L @ G_S, Kzz]])
        self._Kss, self._B, self._L, self._Kzz = Kss, B, L, Kzz
        self._Z_lu = scipy.linalg.lu_factor(Z, check_finite=True) if Z.size else None

    def apply_inverse(self, x: np.ndarray, y: np.ndarray) -> None:
        n, s_count = self.n_fe, self.contact_global.size
        _, r_z, _ = FullSpaceSystem._split(self, x)
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
        n, s_count = self.n_fe, self.contact_global.size
        _, x_z, _ = FullSpaceSystem._split(self, x)
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


def rod_forces(comm, system_class) -> tuple[np.ndarray, np.ndarray, float]:
    """(step times [s], contact force on the wall [N], Saint-Venant force [N]) of the rod impact."""
    rod = RodImpact(elements_along=20)
    system, state = build_rod_impact(comm, rod, TimeScheme.generalized_alpha(0.5), system_class)
    records, _, _ = run_scene(system, state, rod_step_sizes(rod), 1.4 * rod.contact_duration_s)
    system.destroy()
    return (np.array([r["time_s"] for r in records]), np.array([r["contact_force_N"]["rod_wall"][0] for r in records]),
            rod.contact_force_N)


def main(comm=MPI.COMM_WORLD) -> dict:
    t_c, f_c, scale = rod_forces(comm, CoupledSystem)
    t_f, f_f, _ = rod_forces(comm, FullSpaceSystem)
    same_steps = t_c.shape == t_f.shape and bool(np.allclose(t_c, t_f, rtol=1e-12, atol=0.0))
    difference = float(np.max(np.abs(f_c - f_f)) / scale) if same_steps else float("inf")
    if comm.rank == 0:
        print(f"{t_c.size} condensed steps, {t_f.size} full-space steps; largest force difference "
              f"{difference:.2e} of rho c A v0; {np.count_nonzero(f_c)} steps in contact")
    return {"same_steps": same_steps, "force_difference": difference, "contact_steps": int(np.count_nonzero(f_c))}


def check(result: dict) -> None:
    assert result["same_steps"], result
    assert result["contact_steps"] > 20, result
    assert result["force_difference"] <= FORCE_RTOL, result


if __name__ == "__main__":
    check(main())
