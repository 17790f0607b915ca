"""The FE tier's step against its floor, timed over the same steps in the same run.

The floor is one linear Newmark step of the same operator: its right-hand-side mat-vecs (M, K and C when the
case has damping: the three products of the step's predictor residual, app/transient/coupled.py) plus one
back-substitution with the step's prefactorised K_eff (the same LU package). After every accepted FE step the
bench times one floor step and one bare back-substitution, so both see the machine as the FE step saw it (the
machine is shared and its load varies from minute to minute). Reported: medians of the FE step, the floor and the
bare back-substitution, the median of the per-step ratios FE / floor, over all timed steps and over the steps with
a contact closed; the same for the process's CPU time (rank 0), which other jobs on a shared machine disturb less.

An FE step is the time loop's whole iteration (app/transient/stepper.py: the coupled solve with its Newton
iterations, the contact status, the record), without the driver's output (time series, field output: off).

    # the drill (cases/usdc-fe.toml, 10 950 DOFs): 0.5 ms after the first 0.05 ms (durations in closed_s)
    .venv/bin/python bench/bench_fe_floor.py --case cases/usdc-fe.toml --warmup-steps 200 --steps 2000
    # the motor on the pinned mesh (130 168 DOFs): the rotor seated on the harmonic start, its contact closed
    .venv/bin/python bench/bench_fe_floor.py --case bench/cases/wwusm-motor-pinned.toml --set 'tier="fe"' \\
        --warmup-steps 40 --steps 80
    # the same on 2 ranks (MUMPS over the ranks)
    mpirun -n 2 .venv/bin/python bench/bench_fe_floor.py ...

``--profile FILE`` writes a cProfile of the timed steps (rank 0; CPU time, which a loaded machine disturbs less than
wall time).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def floor_step(fe, op, vectors) -> None:
    """One linear Newmark step of ``op``'s operator: the right-hand side's mat-vecs and one solve."""
    x, y, rhs, out = vectors
    rhs.set(0.0)
    for matrix in (fe.M, fe.K, fe.C):
        if matrix is not None:
            matrix.mult(x, y)
            rhs.axpy(1.0, y)
    op.solve(rhs, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, required=True)
    parser.add_argument("--set", nargs="*", default=[], help="--set overrides of the case")
    parser.add_argument("--warmup-steps", type=int, default=40,
                        help="simulate this many closed-contact steps (transient.steps.closed_s) before timing")
    parser.add_argument("--steps", type=int, default=80, help="then time this many closed_s of simulated time")
    parser.add_argument("--profile", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD

    from app.case.schema import load_case
    from app.transient.control import StepController, StepSizes
    from app.transient.driver import build
    from app.transient.stepper import TimeStepper

    start = time.perf_counter()
    case = load_case(args.case, ["output.fields=false", "output.plots=false"] + args.set)
    tm = build(case, comm, lambda *a: None)
    state, _ = tm.initial_state()
    setup_s = time.perf_counter() - start
    system, fe = tm.system, tm.fe
    s = case.transient.steps
    stepper = TimeStepper(system, StepController(StepSizes(s.open_s, s.closed_s, s.change_s, s.min_s)))
    dt = s.closed_s
    state = stepper.run(state, state.t + args.warmup_steps * dt, on_step=None) if args.warmup_steps else state
    vectors = [fe.new_vector() for _ in range(4)]
    vectors[0].array_w[:] = state.u[: fe.n_owned]
    rows = []
    clock = [time.perf_counter(), time.process_time()]
    before = [system.total_iterations, system.jacobians, system.active_dofs]

    def on_step(rec):
        fe_s, fe_cpu = time.perf_counter() - clock[0], time.process_time() - clock[1]
        op = system.op
        comm.Barrier()
        t0, c0 = time.perf_counter(), time.process_time()
        floor_step(fe, op, vectors)
        comm.Barrier()
        t1, c1 = time.perf_counter(), time.process_time()
        op.solve(vectors[2], vectors[3])
        comm.Barrier()
        t2 = time.perf_counter()
        rows.append((fe_s, t1 - t0, t2 - t1, fe_cpu, c1 - c0, bool(np.any(rec["contact_closed"])),
                     system.last_iterations))
        clock[0], clock[1] = time.perf_counter(), time.process_time()

    profile = cProfile.Profile(time.process_time) if args.profile and comm.rank == 0 else None
    if profile:
        profile.enable()
    t_begin = state.t
    clock[0], clock[1] = time.perf_counter(), time.process_time()
    state = stepper.run(state, t_begin + args.steps * dt, on_step=on_step)
    if profile:
        profile.disable()
        profile.dump_stats(str(args.profile))
    data = np.array([r[:5] for r in rows])
    closed = np.array([r[5] for r in rows])
    iterations = np.array([r[6] for r in rows])
    memory_mb = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, root=0)
    jacobians = system.jacobians - before[1]
    active = (system.active_dofs - before[2]) / max(jacobians, 1)

    def summary(mask):
        if not mask.any():
            return None
        fe_s, floor_s, bare_s = (np.median(data[mask, k]) for k in range(3))
        return {"steps": int(mask.sum()), "fe_step_s": fe_s, "floor_s": floor_s, "back_substitution_s": bare_s,
                "median_ratio": float(np.median(data[mask, 0] / data[mask, 1])),
                "total_ratio": float(data[mask, 0].sum() / data[mask, 1].sum()),
                "cpu_median_ratio": float(np.median(data[mask, 3] / data[mask, 4])),
                "cpu_fe_step_s": float(np.median(data[mask, 3])), "cpu_floor_s": float(np.median(data[mask, 4])),
                "newton_iterations_per_step": float(iterations[mask].mean())}

    result = {"case": str(args.case), "sets": args.set, "mpi_size": comm.size, "dofs": fe.M.getSize()[0],
              "contact_dofs": int(system.contact_global.size), "setup_s": setup_s,
              "factor_package": getattr(system.op, "solver_type", None),
              "active_dofs_per_jacobian": active, "peak_rss_mb_per_rank": memory_mb,
              "all": summary(np.ones(len(rows), dtype=bool)), "contact_closed": summary(closed)}
    if comm.rank == 0:
        print(json.dumps(result, indent=1, default=float))
        if args.json:
            args.json.write_text(json.dumps(result, indent=1, default=float))
    system.destroy()


if __name__ == "__main__":
    main()
