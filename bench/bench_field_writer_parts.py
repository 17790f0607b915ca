"""Where the modal tier's field output spends its CPU: the writer's batches (``FieldSeriesExport._write_batch``)
of a real run timed by parts, the expansion (``ReducedVertexFields.expand``: the basis products, von Mises,
principal stresses, |E|, peaks), the HDF5 files (``write_h5_atomic``) and the XML (``_replace_documents``), each
as the CPU time of the thread that runs it; the rest of ``_write_batch`` is Python per frame, the bodies and the
peaks' JSON. Alternates the code trees given (e.g. main's and a branch's), each run a fresh process with the tree
first on ``sys.path``.

    PIEZODYN_CACHE_DIR=/work/wt/cache OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python \\
        bench/bench_field_writer_parts.py /work/main . --repeat 3 [--thread]

Without ``--thread`` the batches are written synchronously by the loop (the writer thread off), so their CPU is not
inflated by the compiled loop stepping on the other core; with it, as in a default run. The case is the drill's
modal tier for 50 ms with default outputs (504 frames), as bench/bench_field_output.py's.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CASE = ["cases/usdc-fe.toml", "--quiet", "--set", "output.plots=false", "--set", 'tier="modal"',
        "--set", "transient.end_time_s=0.05"]

CHILD = r"""
import json, sys, time, collections
import app.transient.fields as F
import app.reduced.engine as E
parts = collections.Counter()
def timed(owner, name, label):
    f = getattr(owner, name)
    def wrapper(*a, **k):
        cpu = time.thread_time()
        try:
            return f(*a, **k)
        finally:
            parts[label] += time.thread_time() - cpu
    setattr(owner, name, wrapper)
timed(F.FieldSeriesExport, "_write_batch", "batches")
timed(E.ReducedVertexFields, "expand", "expand")
timed(F, "write_h5_atomic", "hdf5")
timed(F.FieldSeriesExport, "_replace_documents", "xml")
if not THREAD:
    init = F.FieldSeriesExport.__init__
    def synchronous(self, *a, **k):
        k["writer_thread"] = False
        init(self, *a, **k)
    F.FieldSeriesExport.__init__ = synchronous
from app.cli import main
rc = main(["run", *CASE, "--out", OUT])
print(json.dumps(dict(parts)))
sys.exit(rc)
"""


def run(tree: Path, out: Path, thread: bool) -> dict:
    code = CHILD.replace("THREAD", repr(thread)).replace("CASE", repr(CASE)).replace("OUT", repr(str(out)))
    done = subprocess.run([sys.executable, "-c", code], cwd=tree, capture_output=True, text=True,
                          env={**__import__("os").environ, "PYTHONPATH": str(tree)})
    if done.returncode != 0:
        sys.exit(f"{tree}: run failed:\n{done.stderr[-3000:]}")
    parts = json.loads(done.stdout.strip().splitlines()[-1])
    parts["rest"] = parts["batches"] - parts["expand"] - parts["hdf5"] - parts["xml"]
    return parts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trees", nargs="+", type=Path, help="code trees (each with app/ and cases/)")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--thread", action="store_true", help="the batches on the writer thread, as in a run")
    args = parser.parse_args()
    print("| tree | batches CPU [ms] | expand | HDF5 | XML | rest |\n|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeat):
            for k, tree in enumerate(args.trees):
                p = run(tree.resolve(), Path(tmp) / f"{k}-{repeat}", args.thread)
                print(f"| {tree} | {1e3 * p['batches']:.0f} | {1e3 * p['expand']:.0f} | {1e3 * p['hdf5']:.0f} | "
                      f"{1e3 * p['xml']:.0f} | {1e3 * p['rest']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
