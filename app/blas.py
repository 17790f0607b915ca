"""Keep BLAS single-threaded while transient runs (threadpoolctl).

piezodyn parallelises with MPI ranks (one per core). OpenBLAS's pthread build otherwise starts one
thread per core inside every rank for each small dense product (the n x s contact columns, MUMPS'
fronts, the modal tier's small products); on a shared 2-core machine that oversubscription made the
bordered solve ~5x slower (3.3 s of 6.6 s in one rod-impact run went to a 3606 x 6 mat-vec).
``PIEZODYN_BLAS_THREADS`` overrides the count.
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits


def limit_blas_threads(default: int = 1) -> int:
    """Set the thread count of every BLAS loaded in this process (OpenBLAS, MKL, BLIS); returns it.
    Stays in effect for the rest of the process."""
    count = int(os.environ.get("PIEZODYN_BLAS_THREADS", default))
    threadpool_limits(limits=count, user_api="blas")
    return count
