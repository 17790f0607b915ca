"""A test hook that kills the process at a named point of a run, for the kill-and-resume tests.

``PIEZODYN_KILL_AT=<event>:<n>`` makes the n-th (1-based) call of ``kill_point("<event>")`` in
this process send SIGKILL to itself: no clean-up, no flush, no atexit, like a killed job. Unset (the
normal case) it costs one dictionary look-up. Events (where they are called):

- ``step``: after an accepted FE step was recorded (app/transient/engine.py);
- ``series_block``: the run loop wrote a block of time-series rows (app/loop/loop.py; every tier: at
  each progress step, checkpoint and the end), before the field output and checkpoint that may follow it;
- ``fields_data``: a batch of field frames' HDF5 file is written, the XDMF does not name it yet;
- ``fields_written``: right after a field frame is taken (buffered; app/transient/fields.py);
- ``checkpoint_state``: the checkpoint's state file is written, its JSON not yet;
- ``checkpoint_tmp``: the checkpoint JSON is half written to its temporary file
  (app/loop/checkpoint.py);
- ``harmonic_start``: during the harmonic start, after the steady-state solve, before the first
  output (app/transient/driver.py, app/reduced/engine.py).

Under MPI every rank reaching the event kills itself (rank 0 alone when the event is rank 0's
file I/O); mpirun then ends the others.
"""

from __future__ import annotations

import os
import signal

_counts: dict[str, int] = {}


def kill_point(event: str) -> None:
    spec = os.environ.get("PIEZODYN_KILL_AT")
    if not spec:
        return
    name, _, n = spec.partition(":")
    if name != event:
        return
    _counts[event] = _counts.get(event, 0) + 1
    if _counts[event] == int(n or 1):
        os.kill(os.getpid(), signal.SIGKILL)
