"""Keep OpenBLAS single-threaded while transient runs.

piezodyn parallelises with MPI ranks (one per core). OpenBLAS's pthread build otherwise starts one
thread per core inside every rank for each small dense product (the n x s contact columns, MUMPS'
fronts); on a shared 2-core machine that oversubscription made the bordered solve ~5x slower (3.3 s
of 6.6 s in one rod-impact run went to a 3606 x 6 mat-vec). ``PIEZODYN_BLAS_THREADS`` overrides the
count.
"""

from __future__ import annotations

import ctypes
import os

_done = False


def limit_blas_threads(default: int = 1) -> int | None:
    """Set the OpenBLAS thread count of this process (once); returns the count set, or None if no
    OpenBLAS is loaded (reference BLAS, MKL ... are left alone)."""
    global _done
    if _done:
        return None
    _done = True
    count = int(os.environ.get("PIEZODYN_BLAS_THREADS", default))
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "blas" in line and line.rstrip().endswith(".so")
                     or ("blas" in line and ".so." in line)}
    except OSError:
        return None
    for path in sorted(paths):
        if not os.path.isabs(path):
            continue
        try:
            lib = ctypes.CDLL(path)
            setter = lib.openblas_set_num_threads
        except (OSError, AttributeError):
            continue
        setter(ctypes.c_int(count))
        return count
    return None
