"""CPU and wall time of one modal run's loop (issue 27): the engine's ``advance`` from the case's start to
``END_S``, as the run loop calls it (per-period stops for the site tables included), timed by this process's CPU
clock and the wall clock in the same call, so a loaded machine shows in their difference. ``--root`` imports
``app/`` from another worktree (main's clean clone against a branch, in alternation), whose own venv should run
this script; the case path is taken in that worktree.

    OPENBLAS_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python bench/time_modal_loop.py --root /work/main \\
        bench/cases/wwusm-motor-pinned.toml 0.002 'transient.initial_state="rest"'

Prints one JSON line: steps, Newton iterations, CPU and wall seconds and per step, a checksum of the final state.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case", help="the case file, relative to --root")
    parser.add_argument("end_s", type=float, help="end time [s]")
    parser.add_argument("sets", nargs="*", help="case overrides KEY=VALUE")
    parser.add_argument("--root", default=str(Path(__file__).resolve().parents[1]), help="the worktree to import")
    args = parser.parse_args()
    sys.path.insert(0, args.root)
    import numpy as np
    from mpi4py import MPI

    from app.reduced import kernel as lk
    from app.reduced.engine import ModalEngine
    from app.runner import load_for_run

    case = load_for_run(str(Path(args.root) / args.case), ["output.fields=false", "output.plots=false"] + args.sets)
    engine = ModalEngine(case, MPI.COMM_WORLD, lambda *a, **k: None)
    engine.start()              # loads (or compiles) the kernel: not timed
    cpu, wall = time.process_time(), time.perf_counter()
    engine.advance(args.end_s, 10**9, np.inf)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    steps = engine.steps
    print(json.dumps({"root": args.root, "steps": steps, "newton": int(engine.istate[lk.I_NEWTON]), "cpu_s": cpu,
                      "wall_s": wall,
                      "cpu_ms_per_step": 1e3 * cpu / steps, "wall_ms_per_step": 1e3 * wall / steps,
                      "final_q_sum": float(np.sum(engine.q)), "final_z": engine.z.tolist()}))


if __name__ == "__main__":
    main()
