"""Where a modal step's CPU time goes, by region of the compiled kernel (issue 27): a copy of app/reduced/kernel.py
(the working tree's, or a commit's with ``--kernel``) with libc's ``clock()`` (this process's CPU time, 1 us
resolution, unbiased over thousands of calls) read around the regions of the Newton iteration and of the step, its
sums printed per accepted step. ``perf`` (bench/perf_by_function.py) names the compiled functions but not the
code LLVM inlines into them (most of ``_newton``); this names the regions themselves.

The case (default: the pinned motor on its own mesh) runs with the present kernel from its start (``--rest``: from
rest) to ``--warm-s``; from that state the instrumented kernel takes ``--steps`` steps twice (the first compiles
it), with an empty step-size cache as bench/bench_modal_step.py does ("effective" is that cache's filling: once per
step size and run in a run, here spread over the steps).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python bench/profile_kernel_regions.py --rest --warm-s 0.002
    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python bench/profile_kernel_regions.py --rest --warm-s 0.002 \\
        --kernel 921b40b

The regions are found by lines of the kernel's source (``REGIONS``); one a kernel lacks is reported as absent.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASE = ROOT / "bench" / "cases" / "wwusm-motor-pinned.toml"
#: (slot, name, the first line of the statement timed (stripped), how many lines it spans)
REGIONS = (
    (0, "Newton: first evaluation", "n_active = _evaluate(wk.dd, wk.xi, wk, cp, state, dt, model, True)", 1),
    (1, "Newton: body rows", "_fill_newton_matrix(n_active, wk, cp, model, free_body, dt, False, body_rows, rhs, "
                             "nw.body_pos)", 1),
    (2, "Newton: Woodbury matrix", "_fill_woodbury(n_active, wk, cp, model, free_body, body_rows, cols, nw.col_pos,",
     2),
    (3, "Newton: its LU factors", "_factor(k_s, nw.S[:k_s * k_s].reshape((k_s, k_s)), nw.S_LU, nw.S_ipiv)", 1),
    (4, "Newton: Woodbury solve", "_woodbury_solve_into(nw.S_LU, nw.S_ipiv, D, cols, nw.col_pos, active_rows, "
                                  "n_active, gdim, cp,", 2),
    (5, "Newton: separated sites' corrections", "_respond(cp, wk.active, n_active, gdim, df, cp.du)", 3),
    (6, "Newton: contact-space LU", "_lu_solve(N, J, nw.LU, nw.ipiv, dy)", 1),
    (7, "Newton: trial evaluations", "n_trial = _evaluate(wk.dd_try, wk.xi_try, wk, cp, state, dt, model, True)", 1),
    (8, "Newton: trial solves", "_woodbury_solve_into(nw.S_LU, nw.S_ipiv, D, cols, nw.col_pos, active_rows, "
                                "n_active, gdim, cp,", 2, 1),      # its second call (the first is region 4)
    (9, "Newton (all)", "converged, its = _newton(wk, nw, cp, state, dt_try, model, free_body)", 1),
    (10, "record (outputs, site diagnostics)", "_record(rows, t1, dt_try, q1, pq, wk, state, model, out, closed_new, "
                                               "y_end, record_power, record_seen,", 2),
    (11, "status", "new_closure = _status(y_end, v_end, wk.z1, wk.zd1, wk, model, closed_new_sites, closed_new)", 1),
    (12, "effective (step-size cache)", "slot = _effective(structure, rows_R, dt_try, scheme, cache)", 1),
    (13, "energies", "_record_energy(rows, dt_try, q1, v1, v, structure, bodies, model.sites, model.contacts, wk, "
                     "sums, out)", 1),
)
LOOP = 14


def instrumented(text: str) -> tuple[str, list[str]]:
    """The kernel's source with the timers, and the regions it lacks."""
    text = text.replace("@njit(cache=True", "@njit(cache=False")
    clock = "_clock = ctypes.CDLL('libc.so.6').clock\n_clock.restype = ctypes.c_long\n_clock.argtypes = ()\n"
    text = text.replace("import numpy as np\n", "import ctypes\n\nimport numpy as np\n\n" + clock, 1)
    # the timers ride on the Newton work record (the functions compiled without reference counts take no new array)
    text = text.replace("class NewtonWork(NamedTuple):\n", "class NewtonWork(NamedTuple):\n    timers: np.ndarray\n", 1)
    text = text.replace("    return NewtonWork(", "    return NewtonWork(np.zeros(16), ", 1)
    lines = text.split("\n")
    missing = []
    for slot, name, first, span, *which in REGIONS:
        at = [i for i, line in enumerate(lines) if line.strip() == first or line.strip().startswith(first)]
        occurrence = which[0] if which else 0       # a region whose first line the kernel has more than once
        if len(at) <= occurrence:
            missing.append(name)
            continue
        i = at[occurrence]
        indent = lines[i][:len(lines[i]) - len(lines[i].lstrip())]
        lines[i + span:i + span] = [f"{indent}nw.timers[{slot}] += _clock()"]
        lines[i:i] = [f"{indent}nw.timers[{slot}] -= _clock()"]
    text = "\n".join(lines)
    # the whole loop, and the sums out through the energy rows' spare end (the caller leaves 16 rows free)
    text = text.replace("    while t < t_end * (1.0 - 1e-12):\n",
                        f"    nw.timers[{LOOP}] -= _clock()\n    while t < t_end * (1.0 - 1e-12):\n", 1)
    text = text.replace("    fstate[F_TIME] = t\n    return DONE, rows\n",
                        f"    nw.timers[{LOOP}] += _clock()\n    for k in range(16):\n"
                        "        out.energy[out.energy.shape[0] - 1 - k // 5, k % 5] = nw.timers[k]\n"
                        "    fstate[F_TIME] = t\n    return DONE, rows\n", 1)
    return text, missing


def load(name: str):
    directory = Path(tempfile.mkdtemp(prefix="piezodyn-regions-"))
    if name == "new":
        text = (ROOT / "app" / "reduced" / "kernel.py").read_text()
    else:
        def show(path):
            return subprocess.run(["git", "-C", str(ROOT), "show", f"{name}:{path}"], check=True,
                                  capture_output=True, text=True).stdout

        (directory / "law_regions.py").write_text(show("app/contact/law.py").replace("@njit(cache=True",
                                                                                     "@njit(cache=False"))
        text = show("app/reduced/kernel.py").replace("from app.contact.law import", "from law_regions import")
        sys.path.insert(0, str(directory))
    text, missing = instrumented(text)
    path = directory / "kernel_regions.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("kernel_regions", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["kernel_regions"] = module
    spec.loader.exec_module(module)
    return module, missing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", default=str(CASE))
    parser.add_argument("--set", nargs="*", default=[], help="more case overrides")
    parser.add_argument("--rest", action="store_true", help="start from rest (default: the case's start)")
    parser.add_argument("--warm-s", type=float, default=0.002)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--kernel", default="new", help="'new' (the working tree's) or a git commit")
    args = parser.parse_args()

    from mpi4py import MPI

    from app.reduced.engine import ModalEngine
    from app.runner import load_for_run

    sets = ["output.fields=false", "output.plots=false"] + list(args.set)
    if args.rest:
        sets.append('transient.initial_state="rest"')
    case = load_for_run(args.case, sets)
    engine = ModalEngine(case, MPI.COMM_WORLD, lambda *a, **k: None)
    engine.start()
    engine.advance(args.warm_s, 10**9, np.inf)
    lk, missing = load(args.kernel)
    dt = engine.control.closed_s
    t_end = engine.t + args.steps * dt * (1 + 1e-9)
    keys = ("q", "v", "a", "z", "zd", "zdd", "istate", "fstate")
    for _attempt in range(2):          # the first compiles
        st = {k: getattr(engine, k).copy() for k in keys}
        fields = [st[k] for k in keys] + [lk.Sums(*(a.copy() for a in engine.sums))]
        if "site_force" in lk.State._fields:
            fields.append(engine.site_force.copy())
        state = lk.State(*fields)
        state.fstate[lk.F_STOP] = np.inf
        cap = args.steps + 32
        tables = engine.tables
        site = (tables.sums.copy(), tables.bins.copy(), tables.groups.copy(), tables.phase.copy())
        out = lk.Outputs(*(np.zeros((cap,) + a.shape[1:], a.dtype) for a in engine._out),
                         *site[:len(lk.Outputs._fields) - 15])
        model = lk.Model(engine.structure, engine.inputs_record, engine.scheme, engine.control, engine.bodies_record,
                         engine.sites_record, engine.contacts_record, engine.links_record, engine.sample_rows)
        cache = lk.make_cache(engine.structure.free.size, engine.sites_record.rows.shape[0])
        extra = (lk.no_frames(engine.q.size, engine.z.size),) if hasattr(lk, "Frames") else ()
        mark = time.process_time()
        code, rows = lk.run(t_end, state, model, cache, out, case.output.energies, *extra)
        cpu = time.process_time() - mark
    steps = int(state.istate[lk.I_STEPS] - engine.istate[lk.I_STEPS])
    newton = int(state.istate[lk.I_NEWTON] - engine.istate[lk.I_NEWTON])
    timers = [out.energy[cap - 1 - k // 5, k % 5] for k in range(16)]
    print(f"kernel {args.kernel}: {steps} steps, {newton / steps:.2f} Newton iterations per step, "
          f"{1e3 * cpu / steps:.3f} ms CPU per step (the call), {1e-3 * timers[LOOP] / steps:.3f} ms (the loop, "
          "by clock())")
    print("| region | CPU ms/step |\n|---|---|")
    for slot, name, *_ in REGIONS:
        value = "absent" if name in missing else f"{1e-3 * timers[slot] / steps:.3f}"
        print(f"| {name} | {value} |")


if __name__ == "__main__":
    main()
