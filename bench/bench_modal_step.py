"""Cost of one modal-tier step, by contact state, against one contact-free reduced step, old and new kernel in
the same run (issue 27).

The case (default: the pinned motor case on the tests' coarse stator) runs with the present kernel from its start
to ``--warm-s`` (the state of interest: a seated rotor, or a collapsed one at a heavy preload); from that state

* each kernel named by ``--kernels`` (``new``: app/reduced/kernel.py; a git commit: that commit's
  app/reduced/kernel.py, loaded from git into a temporary module) takes ``--steps`` steps, ``--repeat`` times,
  each from a copy of the same state with an empty step-size cache (its first call compiles and fills the cache
  and is not timed);
* the same kernel takes the same steps with no contact site at all (the contact-free reduced step: the
  predictor, the structure's solve with the cached K_eff^-1, the outputs).

Prints per kernel: ms per step (median of the repeats, and the minimum), Newton iterations per step, mean
active sites, the contact-free step's ms, their ratio, and the largest relative difference of the final
coordinates and body state from the first kernel's (the results must agree to the solver's tolerance).

    .venv/bin/python bench/bench_modal_step.py --kernels 2630325 new --warm-s 0.0005 --steps 400
    .venv/bin/python bench/bench_modal_step.py --kernels 2630325 new --preload 4.116 --rest --warm-s 0.004
    .venv/bin/python bench/bench_modal_step.py --kernels 63b700d new 63b700d new --clock cpu --repeat 9
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASE = ROOT / "bench" / "cases" / "wwusm-motor-pinned.toml"
COARSE = ["geometry.parameters.mesh_size_m=0.003", "geometry.parameters.tip_mesh_size_m=0.001"]


def load_kernel(name: str):
    """The kernel module: ``new`` (the working tree's) or a commit's (from git, a temporary file)."""
    if name == "new":
        from app.reduced import kernel

        return kernel
    def show(path):
        return subprocess.run(["git", "-C", str(ROOT), "show", f"{name}:{path}"], check=True, capture_output=True,
                              text=True).stdout

    directory = Path(tempfile.gettempdir()) / "piezodyn-bench-kernels"
    directory.mkdir(exist_ok=True)
    # that commit's contact law too (the kernel compiles it in): its own module beside the kernel
    law = show("app/contact/law.py").replace("@njit(cache=True", "@njit(cache=False")
    (directory / f"law_{name}.py").write_text(law)
    text = show("app/reduced/kernel.py").replace("from app.contact.law import", f"from law_{name} import")
    path = directory / f"kernel_{name}.py"
    if True:
        path.write_text(text.replace("@njit(cache=True)", "@njit"))
    if str(directory) not in sys.path:
        sys.path.insert(0, str(directory))
    return importlib.import_module(f"kernel_{name}")


def site_outputs(lk, arrays, n_sites):
    """Copies of the per-site diagnostics' accumulators for a kernel's Outputs: since issue 25 the sums (14 columns),
    the wave-frame bins, the sites' groups and phases; before, the sums' first 5 columns alone."""
    sums = arrays[0][:n_sites, :5 if "site_bins" not in lk.Outputs._fields else None].copy()
    if "site_bins" not in lk.Outputs._fields:
        return (sums,)
    bins, groups, phase = arrays[1:] if len(arrays) > 1 else (np.zeros((1, 36, 8)), np.zeros(n_sites, np.int64),
                                                             np.full(n_sites, np.nan))
    return sums, bins.copy(), groups[:n_sites].copy(), phase[:n_sites].copy()


def no_sites(sites):
    """The sites record with no site (the contact-free step)."""
    return type(sites)(*(np.ascontiguousarray(a[:0]) for a in sites))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", default=str(CASE))
    parser.add_argument("--fine", action="store_true", help="the case's own mesh (default: the coarse stator)")
    parser.add_argument("--set", nargs="*", default=[], help="more case overrides")
    parser.add_argument("--preload", type=float, default=None, help="the rotor's axial preload [N]")
    parser.add_argument("--rest", action="store_true", help="start from rest (default: the case's start)")
    parser.add_argument("--warm-s", type=float, default=5e-4)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--kernels", nargs="+", default=["new"])
    parser.add_argument("--json", default=None, help="write the results here")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="time the steps by the wall clock or by this process's CPU time (a loaded machine)")
    args = parser.parse_args()

    from mpi4py import MPI

    from app.reduced.engine import ModalEngine
    from app.runner import load_for_run

    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    sets = ([] if args.fine else COARSE) + ["output.fields=false", "output.plots=false"] + list(args.set)
    if args.preload is not None:
        sets.append(f"transient.bodies[0].applied_force_N=[0.0, 0.0, {-args.preload!r}]")
    if args.rest:
        sets.append('transient.initial_state="rest"')
    case = load_for_run(args.case, sets)
    engine = ModalEngine(case, MPI.COMM_WORLD, lambda *a, **k: None)
    engine.start()
    mark = time.perf_counter()
    engine.advance(args.warm_s, 10**9, np.inf)
    warm_wall = time.perf_counter() - mark
    warm_steps = engine.steps
    state0 = {k: getattr(engine, k).copy() for k in ("q", "v", "a", "z", "zd", "zdd", "istate", "fstate")}
    force0 = engine.site_force.copy() if hasattr(engine, "site_force") else np.zeros((engine.q.size, 3))
    sums0 = [a.copy() for a in engine.sums]
    site_arrays0 = [a.copy() for a in engine._site_outputs()] if hasattr(engine, "_site_outputs") \
        else [engine.site_sums.copy()]
    dt = engine.control.closed_s
    t_end = engine.t + args.steps * dt * (1 + 1e-9)
    results = []
    reference = None
    for name in args.kernels:
        lk = load_kernel(name)
        frames = (lk.no_frames(engine.q.size, engine.z.size),) if hasattr(lk, "Frames") else ()   # since issue 27
        row = {"kernel": name}
        for label, sites in (("contact", engine.sites_record), ("free", no_sites(engine.sites_record))):
            model = lk.Model(engine.structure, engine.inputs_record, engine.scheme, engine.control,
                             engine.bodies_record, sites, engine.contacts_record, engine.links_record,
                             engine.sample_rows)
            walls = []
            for r in range(args.repeat + 1):
                st = {k: v.copy() for k, v in state0.items()}
                sums = lk.Sums(*(a.copy() for a in sums0))
                fields = [st["q"], st["v"], st["a"], st["z"], st["zd"], st["zdd"], st["istate"], st["fstate"], sums]
                if "site_force" in lk.State._fields:      # since issue 27: the Newton start
                    fields.append(force0[:sites.contact.size].copy())
                state = lk.State(*fields)
                state.fstate[lk.F_STOP] = np.inf
                cap = args.steps + 16
                out = lk.Outputs(np.zeros(cap), np.zeros(cap), np.zeros((cap, engine.sample_rows.shape[0])),
                                 np.zeros((cap, engine.structure.inputs.size)), *(np.zeros((cap,) + a.shape[1:])
                                                                                    for a in engine._out[4:10]),
                                 np.zeros((cap,) + engine._out[10].shape[1:], np.bool_),
                                 *(np.zeros((cap,) + a.shape[1:]) for a in engine._out[11:]),
                                 *site_outputs(lk, site_arrays0, sites.contact.size))
                cache = lk.make_cache(engine.structure.free.size, sites.rows.shape[0])
                n_site = len(out) - 15
                if r == 0:         # compile, fill the cache: not timed
                    lk.run(t_end, state, model, cache, lk.Outputs(*(a[:1] for a in out[:-n_site]), *out[-n_site:]),
                           case.output.energies, *frames)
                    continue
                mark = clock()
                code, rows = lk.run(t_end, state, model, cache, out, case.output.energies, *frames)
                walls.append(clock() - mark)
            steps = int(state.istate[lk.I_STEPS] - state0["istate"][lk.I_STEPS])
            newton = int(state.istate[lk.I_NEWTON] - state0["istate"][lk.I_NEWTON])
            row[label] = {"ms_per_step_median": 1e3 * float(np.median(walls)) / steps,
                          "ms_per_step_min": 1e3 * min(walls) / steps, "steps": steps,
                          "newton_per_step": newton / steps, "code": int(code),
                          "cutbacks": int(state.istate[lk.I_CUTBACKS] - state0["istate"][lk.I_CUTBACKS]),
                          "mean_area_m2": float(out.area[:rows, 0].mean()) if out.area.shape[1] else 0.0}
            if label == "contact":
                final = np.concatenate([state.q, state.z, state.zd])
                torque = out.torque[:rows, 0, 2].mean() if out.torque.shape[1] else 0.0
                row["final"] = final
                row["mean_torque_N_m"] = float(torque)
                row["mean_normal_N"] = float(out.normal[:rows, 0].mean()) if out.normal.shape[1] else 0.0
        row["ratio_to_contact_free"] = row["contact"]["ms_per_step_median"] / row["free"]["ms_per_step_median"]
        if reference is None:
            reference = row
        else:
            a, b = reference["final"], row["final"]
            n = engine.q.size
            # the structure's coordinates against their largest; each body coordinate and rate against itself
            rel_q = np.max(np.abs(a[:n] - b[:n])) / np.max(np.abs(a[:n]))
            rel_z = np.max(np.abs(a[n:] - b[n:]) / np.maximum(np.abs(a[n:]), 1e-300))
            row["max_rel_diff_final"] = float(max(rel_q, rel_z))
            for key in ("mean_torque_N_m", "mean_normal_N"):
                if reference[key] != 0.0:
                    row[key.replace("mean_", "rel_diff_")] = row[key] / reference[key] - 1
        results.append(row)
        printable = {k: v for k, v in row.items() if k != "final"}
        print(json.dumps(printable), flush=True)
    print(f"# warm-up: {warm_steps} steps to t = {engine.t:.4e} s in {warm_wall:.1f} s "
          f"({1e3 * warm_wall / max(warm_steps, 1):.3f} ms/step, present kernel)")
    print("| kernel | ms/step (median, min) | Newton/step | contact-free ms/step | ratio | final rel. diff |")
    print("|---|---|---|---|---|---|")
    for row in results:
        c, f = row["contact"], row["free"]
        print(f"| {row['kernel']} | {c['ms_per_step_median']:.3f}, {c['ms_per_step_min']:.3f} | "
              f"{c['newton_per_step']:.2f} | {f['ms_per_step_median']:.4f} | {row['ratio_to_contact_free']:.1f} | "
              f"{row.get('max_rel_diff_final', 0.0):.2e} |")
    if args.json:
        Path(args.json).write_text(json.dumps([{k: v for k, v in r.items() if k != "final"} for r in results],
                                              indent=1))


if __name__ == "__main__":
    main()
