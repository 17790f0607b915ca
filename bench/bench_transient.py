"""Wall time per simulated ms of the transient contact solver on the rod-impact scene.

(a) this implementation: K_eff factorised once per dt, one back-substitution per step, Newton on
    the contact forces and rigid DOFs only (app/transient/coupled.py);
(b) naive dolfinx loop: Newton on all FE + rigid DOFs (demos/demo_fullspace.py) with M and K
    re-assembled from their forms and K_eff built and re-factorised at every Newton iteration;
(c) floor: a linear Newmark step with a pre-factorised K_eff (two mat-vecs for the right-hand side
    and one back-substitution) for every step (a) took; also the bare back-substitution alone.
Errors of (a) and (b): relative L2 of the contact force history vs a 4x finer-dt run of (a).

    /work/main/.venv/bin/python bench/bench_transient.py [--elements 300] [--drill-ms 0.1]

300 P2 elements along the rod = 1803 nodes, the drill paper's mesh scale (~1800 nodes).
``--drill-ms T`` also runs (a), (b) and (c) on the first T ms of the drill scene
(cases/usdc-fe.toml, default mesh, harmonic start, 0 N); error there = relative L2 of the ball's
displacement history against (a) at 4x finer step sizes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.transient.coupled import CoupledSystem  # noqa: E402
from app.transient.fe import EffectiveOperator  # noqa: E402
from app.transient.stepper import run_scene  # noqa: E402
from demos.demo_fullspace import FullSpaceSystem  # noqa: E402
from demos.demo_rod_impact import RodImpact, build_rod_impact, rod_step_sizes  # noqa: E402
from forms.newmark import TimeScheme  # noqa: E402


class RefactorEveryIteration(FullSpaceSystem):
    """(b): Newton on all FE + rigid unknowns that rebuilds and refactorises K_eff (and its contact
    columns) in every Jacobian call."""

    def _contact_free_step(self, atol):
        return None     # the naive loop goes through SNES (and refactorises) on every step

    def _jacobian_callback(self, snes, X, J, P):
        previous = getattr(self, "_naive_op", None)
        if previous is not None:
            previous.destroy()
        fe = self.fe
        for name, attr in (("mass", "M"), ("stiffness", "K")):
            old = getattr(fe, attr)
            setattr(fe, attr, fe._assemble(fe.forms[name]))
            old.destroy()
        self.op = self._naive_op = EffectiveOperator(self.fe, self.dt, self.scheme, self.contact_global)
        self.cache.factorisations += 1
        super()._jacobian_callback(snes, X, J, P)


def force_history(records):
    return np.array([r["time_s"] for r in records]), np.array([r["contact_force_N"].get("rod_wall", [0.0])[0]
                                                               for r in records])


def run(rod, sizes, system_class=CoupledSystem):
    system, state = build_rod_impact(MPI.COMM_WORLD, rod, TimeScheme.generalized_alpha(0.5), system_class)
    start = time.perf_counter()
    records, _, stepper = run_scene(system, state, sizes, 1.4 * rod.contact_duration_s)
    return time.perf_counter() - start, records, stepper.stats


def run_drill(end_s, system_class=CoupledSystem, refine=1.0):
    """One run of the drill scene to ``end_s``: (wall s of the time loop, ball displacement
    history (t, z - z0), statistics, the system)."""
    import app.transient.driver as driver
    from app.case.schema import load_case
    from app.transient.control import StepController, StepSizes
    from app.transient.stepper import TimeStepper

    case = load_case(Path(__file__).resolve().parents[1] / "cases" / "usdc-fe.toml",
                     [f"transient.end_time_s={end_s!r}"])
    original = driver.CoupledSystem
    driver.CoupledSystem = system_class
    try:
        tm = driver.TransientModel(case, MPI.COMM_WORLD, lambda *a: None)
    finally:
        driver.CoupledSystem = original
    state, _ = tm.initial_state()
    s = case.transient.steps
    sizes = StepSizes(open_s=s.open_s / refine, closed_s=s.closed_s / refine, change_s=s.change_s / refine,
                      min_s=s.min_s)
    stepper = TimeStepper(tm.system, StepController(sizes))
    ball = tm.rigid.dofs("ball")
    z0 = state.z[ball][-1]
    hist = []
    start = time.perf_counter()
    stepper.run(state, end_s, on_step=lambda rec: hist.append((rec["time_s"], rec["position_m"][ball][-1] - z0)))
    wall = time.perf_counter() - start
    return wall, np.array(hist), stepper.stats, tm.system


def drill(end_ms):
    end_s = end_ms * 1e-3
    _, ref, _, _ = run_drill(end_s, refine=4.0)
    rows = []
    for label, cls in (("(a) factor once per dt + condensed contact Newton", CoupledSystem),
                       ("(b) refactorise every Newton iteration", RefactorEveryIteration)):
        wall, hist, stats, system = run_drill(end_s, cls)
        err = np.sqrt(np.trapz((np.interp(ref[:, 0], hist[:, 0], hist[:, 1]) - ref[:, 1]) ** 2, ref[:, 0])
                      / np.trapz(ref[:, 1] ** 2, ref[:, 0]))
        rows.append((label, wall / end_ms, stats.steps, stats.newton_iterations, stats.factorisations, err))
        if cls is CoupledSystem:
            steps, op_dt, floor_system = stats.steps, stats.dt_min_used_s, system
        else:
            system.destroy()
    fe = floor_system.fe
    op = floor_system.cache.get(op_dt)
    rhs, out, tmp = fe.new_vector(), fe.new_vector(), fe.new_vector()
    rhs.set(1.0)
    start = time.perf_counter()
    for _ in range(steps):
        fe.M.mult(rhs, tmp)
        fe.K.mult(rhs, out)
        op.solve(tmp, out)
    floor = time.perf_counter() - start
    rows.append(("(c) floor: linear Newmark step (2 mat-vecs + 1 solve) per step of (a)", floor / end_ms,
                 steps, 0, 1, float("nan")))
    if MPI.COMM_WORLD.rank == 0:
        print(f"drill scene (cases/usdc-fe.toml), {fe.n_owned} owned DOFs on rank 0, {end_ms} ms simulated, "
              f"MPI size {MPI.COMM_WORLD.size}, K_eff LU: {getattr(op, 'solver_type', 'mumps')}")
        print("| variant | wall s per simulated ms | steps | Newton its | factorisations | rel. L2 ball error |")
        print("|---|---|---|---|---|---|")
        for label, per_ms, n, its, facts, err in rows:
            print(f"| {label} | {per_ms:.3g} | {n} | {its} | {facts} | {err:.2e} |")
    floor_system.destroy()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--elements", type=int, default=300)
    parser.add_argument("--drill-ms", type=float, default=0.0, help="also run the drill scene for this long")
    parser.add_argument("--skip-rod", action="store_true")
    args = parser.parse_args()
    if args.drill_ms > 0:
        drill(args.drill_ms)
    if args.skip_rod:
        return
    rod = RodImpact(elements_along=args.elements, degree=2)
    sizes = rod_step_sizes(rod)
    fine = rod_step_sizes(rod, steps_per_element=4.0)
    simulated_ms = 1.4 * rod.contact_duration_s * 1e3
    _, ref_records, _ = run(rod, fine)
    t_ref, f_ref = force_history(ref_records)
    rows = []
    wall_a = None
    for label, cls in (("(a) factor once per dt + condensed contact Newton", CoupledSystem),
                       ("(b) refactorise every Newton iteration", RefactorEveryIteration)):
        wall, records, stats = run(rod, sizes, cls)
        t, f = force_history(records)
        err = np.sqrt(np.trapz((np.interp(t_ref, t, f) - f_ref) ** 2, t_ref) / np.trapz(f_ref**2, t_ref))
        rows.append((label, wall / simulated_ms, stats.steps, stats.newton_iterations, stats.factorisations, err))
        wall_a = wall_a or (wall, stats.steps)
    # (c) the floor: a linear Newmark step (M and K mat-vecs for the right-hand side, one
    # back-substitution with a pre-factorised K_eff) for every step (a) took.
    system, _ = build_rod_impact(MPI.COMM_WORLD, rod, TimeScheme.generalized_alpha(0.5))
    fe = system.fe
    op = system.cache.get(sizes.closed_s)
    rhs, out, tmp = fe.new_vector(), fe.new_vector(), fe.new_vector()
    rhs.set(1.0)
    steps = wall_a[1]
    start = time.perf_counter()
    for _ in range(steps):
        fe.M.mult(rhs, tmp)
        fe.K.mult(rhs, out)
        op.solve(tmp, out)
    floor = time.perf_counter() - start
    start = time.perf_counter()
    for _ in range(steps):
        op.solve(rhs, out)
    bare = time.perf_counter() - start
    rows.append(("(c) floor: linear Newmark step (2 mat-vecs + 1 solve) per step of (a)", floor / simulated_ms,
                 steps, 0, 1, float("nan")))
    rows.append(("(c') one bare back-substitution per step of (a)", bare / simulated_ms, steps, 0, 1, float("nan")))
    if MPI.COMM_WORLD.rank == 0:
        nodes = (2 * args.elements + 1) * 3
        print(f"rod impact, P2 plane strain, {args.elements} x 1 elements, {nodes} nodes, {2 * nodes} DOFs, "
              f"{simulated_ms:.4f} ms simulated, MPI size {MPI.COMM_WORLD.size}")
        print("| variant | wall s per simulated ms | steps | Newton its | factorisations | rel. L2 force error |")
        print("|---|---|---|---|---|---|")
        for label, per_ms, steps, its, facts, err in rows:
            print(f"| {label} | {per_ms:.3g} | {steps} | {its} | {facts} | {err:.2e} |")


if __name__ == "__main__":
    main()
