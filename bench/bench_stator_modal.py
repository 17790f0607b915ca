"""3D modal of the wedge-wave stator (cases/wwusm-stator.toml) at a given mesh size: wall time and
peak memory (ru_maxrss of every rank), 1 rank against 2 ranks at one BLAS thread each; the peer is
the same solve on the other rank count, compared for time, memory and F(1,4).

    .venv/bin/python bench/bench_stator_modal.py 0.0008 [0.0006 ...]   # mesh sizes [m], markdown rows
    .venv/bin/python bench/bench_stator_modal.py --single 0.0008          # one run (used internally)

The tip mesh size is 0.42 x the mesh size (as in the case). Under load, wall time includes waiting
for the CPU: the CPU time of rank 0 is reported too.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def single(mesh_size_m: float) -> dict:
    from mpi4py import MPI

    from app.case.schema import load_case
    from app.fe.model import build_model
    from app.fe.operators import assemble_operators
    from app.modal import run_modal

    comm = MPI.COMM_WORLD
    t_start = time.perf_counter()
    case = load_case(ROOT / "cases/wwusm-stator.toml",
                     [f"geometry.parameters.mesh_size_m={mesh_size_m!r}",
                      f"geometry.parameters.tip_mesh_size_m={0.42 * mesh_size_m!r}", 'analyses=["modal"]'])
    model = build_model(case, comm)
    t_mesh = time.perf_counter() - t_start
    t0 = time.perf_counter()
    ops = assemble_operators(model)
    t_assemble = time.perf_counter() - t0
    t0 = time.perf_counter()
    modal = run_modal(model, ops)
    t_modal = time.perf_counter() - t0
    order = modal.orders[modal.working]
    f14 = sorted([modal.working_mode.frequency_Hz, modal.short[order.partner].frequency_Hz])
    usage = resource.getrusage(resource.RUSAGE_SELF)
    rss = comm.gather(usage.ru_maxrss / 1024.0, root=0)
    return {"mesh_size_m": mesh_size_m, "dofs": model.W.dofmap.index_map.size_global, "ranks": comm.size,
            "mesh_s": t_mesh, "assemble_s": t_assemble, "modal_s": t_modal,
            "cpu_s_rank0": usage.ru_utime + usage.ru_stime, "F14_low_Hz": f14[0], "F14_high_Hz": f14[1],
            "peak_rss_MB_per_rank": rss}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("sizes", nargs="*", type=float)
    parser.add_argument("--single", type=float)
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    if args.single:
        result = single(args.single)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(result), flush=True)
        return
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OPENBLAS_NUM_THREADS="1",
               OMP_NUM_THREADS="1")
    print("| mesh size [mm] | DOFs | ranks | mesh [s] | assemble [s] | modal [s] | CPU rank 0 [s] | "
          "peak RSS per rank [MB] | F(1,4) pair [Hz] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for size in args.sizes:
        for ranks in args.ranks:
            cmd = [sys.executable, __file__, "--single", repr(size)]
            if ranks > 1:
                cmd = ["mpirun", "-n", str(ranks), "-x", "OPENBLAS_NUM_THREADS=1", "-x", "OMP_NUM_THREADS=1", *cmd]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
            if not line:
                print(proc.stderr[-2000:], file=sys.stderr)
                continue
            r = json.loads(line[0][7:])
            rss = " / ".join(f"{v:.0f}" for v in r["peak_rss_MB_per_rank"])
            print(f"| {size * 1e3:.2f} | {r['dofs']} | {r['ranks']} | {r['mesh_s']:.1f} | {r['assemble_s']:.1f} | "
                  f"{r['modal_s']:.1f} | {r['cpu_s_rank0']:.1f} | {rss} | {r['F14_low_Hz']:.1f} / "
                  f"{r['F14_high_Hz']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
