"""Rank-0 printing and timers."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from mpi4py import MPI


def make_log(comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False):
    def log(message: str) -> None:
        if comm.rank == 0 and not quiet:
            print(message, file=sys.stdout, flush=True)

    return log


class PhaseTimer:
    """Wall time per named phase [s], as reported in summary.json."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    @contextmanager
    def phase(self, name: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start
