"""Progress reports for long runs (transient time loop, sweeps), rank 0 only.

In a terminal: a tqdm bar, redrawn in place. In a batch job (stderr redirected to a file or pipe, or a
terminal that reports zero columns) a bar would write a carriage-return update every second onto one
endless line, so instead one plain line is written every 10 % of the work:

    transient:  30 % | 0.060/0.200 simulated ms | wall 00:12 | ETA 00:28

``silenced()`` turns every report off for the code inside it (a sweep's points, ``run --quiet``).
"""

from __future__ import annotations

import math
import os
import sys
import time
from contextlib import contextmanager

_SILENCED = [0]


@contextmanager
def silenced(active: bool = True):
    """No progress output from reports created inside this block (when ``active``)."""
    _SILENCED[0] += int(active)
    try:
        yield
    finally:
        _SILENCED[0] -= int(active)


def is_terminal(stream) -> bool:
    """True for an interactive terminal with a usable width (a bar can redraw in place)."""
    try:
        if not stream.isatty():
            return False
        return os.get_terminal_size(stream.fileno()).columns > 0
    except (AttributeError, OSError, ValueError):
        return False


def format_interval(seconds: float) -> str:
    """[h:]mm:ss as tqdm prints it."""
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours:d}:{minutes:02d}:{secs:02d}" if hours else f"{minutes:02d}:{secs:02d}"


class Progress:
    """Progress towards ``total`` (in ``unit``); ``update_to(n)`` sets the amount done.

    ``mode`` is "bar" (terminal), "lines" (batch) or None (disabled, non-zero rank or silenced).
    ``value_format`` formats the done/total numbers ("{:.0f}" for counts, "{:.3f}" for ms).
    """

    def __init__(self, total: float, desc: str, unit: str, *, enabled: bool = True, rank: int = 0,
                 stream=None, every_percent: int = 10, value_format: str = "{:.3f}", clock=time.monotonic):
        self.total = float(total)
        self.desc, self.unit, self.value_format = desc, unit, value_format
        self.stream = sys.stderr if stream is None else stream
        self.every_percent = every_percent
        self.clock = clock
        self.n = 0.0
        self.bar = None
        self.mode = None
        if enabled and rank == 0 and not _SILENCED[0]:
            self.mode = "bar" if is_terminal(self.stream) else "lines"
        self._start = clock()
        self._next_percent = every_percent
        self._last_line_n = None
        if self.mode == "bar":
            from tqdm import tqdm

            fmt, total_fmt = "{n" + value_format[1:], "{total" + value_format[1:]  # "{:.3f}" -> "{n:.3f}"
            self.bar = tqdm(total=self.total, desc=desc, file=self.stream, mininterval=1.0,
                            bar_format="{l_bar}{bar}| " + fmt + "/" + total_fmt + f" {unit} "
                            "[{elapsed}<{remaining}]")

    def update_to(self, n: float) -> None:
        """Set the amount done (clamped to [previous, total]; it never goes back)."""
        n = min(max(float(n), self.n), self.total)
        if self.bar is not None and n > self.n:
            self.bar.update(n - self.n)
        self.n = n
        if self.mode == "lines":
            percent = self._percent()
            if percent >= self._next_percent:
                self._write_line()
                self._next_percent = (percent // self.every_percent + 1) * self.every_percent

    def update(self, dn: float = 1.0) -> None:
        self.update_to(self.n + dn)

    def _percent(self) -> int:
        if self.total <= 0:
            return 100
        return int(math.floor(100.0 * self.n / self.total + 1e-9))

    def line(self) -> str:
        """The batch line for the current state."""
        elapsed = self.clock() - self._start
        done = self.value_format.format(self.n)
        total = self.value_format.format(self.total)
        if 0 < self.n < self.total:
            eta = format_interval(elapsed * (self.total - self.n) / self.n)
        elif self.n >= self.total:
            eta = "00:00"
        else:
            eta = "?"
        return (f"{self.desc}: {self._percent():3d} % | {done}/{total} {self.unit} | "
                f"wall {format_interval(elapsed)} | ETA {eta}")

    def _write_line(self) -> None:
        print(self.line(), file=self.stream, flush=True)
        self._last_line_n = self.n

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.mode == "lines" and self._last_line_n != self.n:
            self._write_line()  # where a stopped run ended
        self.mode = None


class SimulatedTimeProgress(Progress):
    """A transient run's progress in simulated milliseconds: ``update(t_s)`` with the current time [s]."""

    def __init__(self, comm, t_start_s: float, t_end_s: float, enabled: bool = True, stream=None,
                 clock=time.monotonic):
        super().__init__(round((t_end_s - t_start_s) * 1e3, 6), "transient", "simulated ms", enabled=enabled,
                         rank=comm.rank, stream=stream, value_format="{:.3f}", clock=clock)
        self.t_start_s = t_start_s

    def update(self, t_s: float) -> None:  # type: ignore[override]
        self.update_to((t_s - self.t_start_s) * 1e3)
