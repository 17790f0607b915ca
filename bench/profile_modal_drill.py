"""Where a modal drill step's time goes (issue 27): the compiled loop's CPU time per step, the cost of one compiled
call that takes no step (numba's dispatch: typing the records), and, for a profile of the compiled code with
``perf``, the addresses of the compiled functions (the loop's library, when it was compiled in this process).

The drill case (cases/usdc-fe.toml, modal tier, default mesh, harmonic start, downforce ``--force``) advances from
its start to ``--ms``; CPU time (``time.process_time``) rather than wall time, so a loaded machine inflates it
less. A profile of the compiled code:

    NUMBA_CACHE_DIR=$(mktemp -d) perf record -F 4000 -g -o perf.data .venv/bin/python bench/profile_modal_drill.py \
        --addresses addresses.json
    perf script -i perf.data -F time,ip,sym,dso > samples.txt
    .venv/bin/python bench/perf_by_function.py samples.txt addresses.json     # samples by function

(a fresh numba cache compiles the loop in the process, so its functions' addresses are known; NRT_incref and
NRT_decref are numba's reference counts).

``--coordinates free physical free physical`` runs the drill once per entry, in this order, in one process: ``free``
as the engine chooses (its free modes, app/reduced/coordinates.py), ``physical`` with the free modes turned off
(the model as built: the kernel's dense path, as before issue 27's free modes), so both paths are timed under the
same load.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from mpi4py import MPI

from app.reduced import engine as reduced_engine
from app.reduced import kernel as lk
from app.reduced.engine import ModalEngine
from app.runner import load_for_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", type=float, default=9.0, help="downforce [N]")
    parser.add_argument("--ms", type=float, default=20.0, help="simulated time [ms]")
    parser.add_argument("--addresses", default=None, help="write the compiled functions' addresses here (JSON)")
    parser.add_argument("--coordinates", nargs="+", choices=("free", "physical"), default=["free"],
                        help="the runs, in order: the engine's choice (free modes) or the model as built")
    args = parser.parse_args()
    for coordinates in args.coordinates:
        _one(args, coordinates)


def _one(args, coordinates: str) -> None:
    chosen = reduced_engine.free_modes
    if coordinates == "physical":
        reduced_engine.free_modes = lambda *a, **k: None
    case = load_for_run("cases/usdc-fe.toml", ['tier="modal"', "output.fields=false", "output.plots=false",
                                               f"transient.loads.fe_force_N=[0.0,{-args.force!r}]"])
    try:
        engine = ModalEngine(case, MPI.COMM_WORLD, lambda *a, **k: None)
    finally:
        reduced_engine.free_modes = chosen
    print(f"-- {coordinates}: the model {'in its free modes' if engine.free_modes is not None else 'as built'}")
    mark = time.perf_counter()
    engine.start()
    print(f"start (model, harmonic start, loading or compiling the loop): {time.perf_counter() - mark:.1f} s")
    calls = 200
    mark = time.perf_counter()
    for _ in range(calls):
        out = lk.Outputs(*(arr[:100] for arr in engine._out), *engine._site_outputs())
        lk.run(engine.t, engine._state(), engine._model(), engine.cache, out, False, engine.frames)
    print(f"one compiled call taking no step: {(time.perf_counter() - mark) / calls * 1e3:.3f} ms")
    cpu, wall = time.process_time(), time.perf_counter()
    engine.advance(args.ms * 1e-3, 10**9, np.inf)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    steps = engine.steps
    print(f"{args.ms:g} ms, {steps} steps: {wall:.2f} s wall, {cpu:.2f} s CPU, "
          f"{cpu / engine.steps * 1e6:.2f} us CPU per step, {cpu / args.ms:.4f} s CPU per simulated ms")
    if args.addresses:
        library = next(iter(lk.run.overloads.values())).library
        module = getattr(library, "_final_module", None)
        found = {}
        for function in (module.functions if module is not None else []):
            if not function.is_declaration:
                address = library.get_pointer_to_function(function.name)
                if address:
                    found[function.name] = address
        with open(args.addresses, "w") as fh:
            json.dump(found, fh)
        print(f"{len(found)} function addresses (none: the loop came from the cache)")


if __name__ == "__main__":
    main()
