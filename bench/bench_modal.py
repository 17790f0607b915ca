"""3D modal solve: wall time and peak memory against DOFs, serial and on 2 MPI ranks, with
scipy's ARPACK shift-invert (eigsh + SuperLU) as the peer on the same matrices.

    .venv/bin/python bench/bench_modal.py            # all sizes, prints a markdown table
    .venv/bin/python bench/bench_modal.py --single LAT AXIAL [--peer]   # one size (used internally)

Work: the PZT-4 33-bar of cases/validation/pzt4-bar-3d.toml (P2, short circuit, 12 modes nearest
70 kHz). Error: the length-extensional resonance against the IEEE Std 176 closed form.
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
sys.path.insert(0, str(ROOT / "tests"))
SIZES = [(2, 16), (4, 30), (6, 50), (8, 70), (10, 100)]
PEER_MAX_DOFS = 120_000  # SuperLU on larger 3D P2 problems takes minutes and GBs


def single(lat: int, axial: int, peer: bool) -> dict:
    import numpy as np
    from ieee176 import bar_33
    from mpi4py import MPI

    from app.case.schema import load_case
    from app.fe.model import build_model
    from app.fe.operators import assemble_operators, electrical_state
    from app.materials import LIBRARY
    from app.modal import run_modal

    comm = MPI.COMM_WORLD
    case = load_case(ROOT / "cases/validation/pzt4-bar-3d.toml",
                     [f"geometry.parameters.lateral_divisions={lat}", f"geometry.parameters.axial_divisions={axial}",
                      'modal.electrical="short"', 'modal.working_mode="nearest"', "modal.target_frequency_Hz=76e3"])
    model = build_model(case, comm)
    t0 = time.perf_counter()
    ops = assemble_operators(model)
    t_assemble = time.perf_counter() - t0
    t0 = time.perf_counter()
    modal = run_modal(model, ops)
    t_modal = time.perf_counter() - t0
    c, e, eps = LIBRARY["PZT-4"].tensors()
    f_r, _, _ = bar_33(c, e, eps, 7500.0, 0.02)
    f_fe = modal.working_mode.frequency_Hz
    out = {"dofs": model.W.dofmap.index_map.size_global, "ranks": comm.size, "assemble_s": t_assemble,
           "modal_s": t_modal, "f_Hz": f_fe, "error": abs(f_fe - f_r) / f_r}
    if peer and comm.size == 1:
        import scipy.sparse as sp
        from scipy.sparse.linalg import eigsh

        cs = electrical_state(model, "short")
        K, M = cs.reduce(ops.K), cs.reduce(ops.M)
        cs.apply(K, 1.0)
        cs.apply(M, 0.0)
        Ks = sp.csr_matrix(K.getValuesCSR()[::-1], shape=K.getSize())
        Ms = sp.csr_matrix(M.getValuesCSR()[::-1], shape=M.getSize())
        t0 = time.perf_counter()
        sigma = (2 * np.pi * 76e3) ** 2
        vals = eigsh(Ks, k=12, M=Ms, sigma=sigma, which="LM", return_eigenvectors=False)
        t_peer = time.perf_counter() - t0
        freqs = np.sqrt(np.abs(vals)) / (2 * np.pi)
        f_peer = freqs[np.argmin(np.abs(freqs - f_fe))]
        out.update(peer_s=t_peer, peer_f_Hz=float(f_peer), peer_error=abs(f_peer - f_r) / f_r)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    out["peak_rss_MB_per_rank"] = comm.allreduce(rss, op=MPI.MAX)
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--single", nargs=2, type=int)
    parser.add_argument("--peer", action="store_true")
    parser.add_argument("--max-size", type=int, default=len(SIZES))
    args = parser.parse_args()
    if args.single:
        result = single(*args.single, args.peer)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(result), flush=True)
        return
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    rows = []
    for lat, axial in SIZES[: args.max_size]:
        for ranks in (1, 2):
            cmd = [sys.executable, __file__, "--single", str(lat), str(axial)]
            dofs_estimate = 4 * (2 * lat + 1) ** 2 * (2 * axial + 1)
            if ranks == 1 and dofs_estimate <= PEER_MAX_DOFS:
                cmd.append("--peer")
            if ranks > 1:
                # one BLAS thread per rank: 2 ranks already fill the 2 cores
                cmd = ["mpirun", "-n", str(ranks), "-x", "OPENBLAS_NUM_THREADS=1", *cmd]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
            if not line:
                print(proc.stderr[-2000:], file=sys.stderr)
                continue
            rows.append(json.loads(line[0][7:]))
            r = rows[-1]
            peer = (f"{r['peer_s']:.2f} s, err {r['peer_error']:.2e}, ratio {r['peer_s'] / r['modal_s']:.1f}x"
                    if "peer_s" in r else "-")
            print(f"| {r['dofs']} | {r['ranks']} | {r['assemble_s']:.2f} | {r['modal_s']:.2f} | "
                  f"{r['peak_rss_MB_per_rank']:.0f} | {r['error']:.2e} | {peer} |", flush=True)


if __name__ == "__main__":
    main()
