"""Progress reports: a plain line every 10 % in batch logs, a tqdm bar in a terminal (app/progress.py)."""

from __future__ import annotations

import fcntl
import io
import os
import struct
import termios
from types import SimpleNamespace

import pytest

from app.progress import Progress, SimulatedTimeProgress, is_terminal, silenced


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _pty(columns: int):
    """A pseudo-terminal (master, slave file) whose window is ``columns`` wide."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    return master, os.fdopen(slave, "w", buffering=1)


def _read_all(master) -> str:
    os.set_blocking(master, False)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except (BlockingIOError, OSError):
            break
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks).decode(errors="replace")


def test_batch_log_writes_one_plain_line_per_ten_percent():
    stream, clock = io.StringIO(), FakeClock()
    progress = SimulatedTimeProgress(SimpleNamespace(rank=0), 0.0, 2e-4, stream=stream, clock=clock)
    assert progress.mode == "lines"
    n_updates = 1000
    for i in range(1, n_updates + 1):  # 1000 steps of 0.2 us simulated, 0.01 s wall each
        clock.t = 0.01 * i
        progress.update(2e-4 * i / n_updates)
    progress.close()
    text = stream.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 10
    assert lines[0] == "transient:  10 % | 0.020/0.200 simulated ms | wall 00:01 | ETA 00:09"
    assert lines[4].startswith("transient:  50 % | 0.100/0.200 simulated ms | wall 00:05 | ETA 00:05")
    assert lines[-1].startswith("transient: 100 % | 0.200/0.200 simulated ms | wall 00:10 | ETA 00:00")


def test_batch_log_big_jumps_and_stopped_run():
    stream, clock = io.StringIO(), FakeClock()
    progress = Progress(4, "sweep", "points", stream=stream, value_format="{:.0f}", clock=clock)
    clock.t = 30.0
    progress.update(1)  # 25 %: one line, not three
    clock.t = 60.0
    progress.update(1)
    progress.close()  # stopped at 2 of 4: no duplicate line
    lines = stream.getvalue().splitlines()
    assert lines == ["sweep:  25 % | 1/4 points | wall 00:30 | ETA 01:30",
                     "sweep:  50 % | 2/4 points | wall 01:00 | ETA 01:00"]


def test_silenced_and_other_ranks_write_nothing():
    stream = io.StringIO()
    with silenced():
        quiet = Progress(10, "x", "u", stream=stream)
    other_rank = SimulatedTimeProgress(SimpleNamespace(rank=1), 0.0, 1.0, stream=stream)
    for p in (quiet, other_rank):
        assert p.mode is None
        p.update_to(10)
        p.close()
    assert stream.getvalue() == ""
    assert Progress(10, "x", "u", stream=stream).mode == "lines"  # silencing ends with the block


@pytest.mark.parametrize("columns, expected", [(80, "bar"), (0, "lines")])
def test_terminal_gets_a_bar_zero_width_terminal_gets_lines(columns, expected):
    master, tty = _pty(columns)
    try:
        assert is_terminal(tty) is (expected == "bar")
        progress = SimulatedTimeProgress(SimpleNamespace(rank=0), 0.0, 1e-3, stream=tty)
        assert progress.mode == expected
        for i in range(1, 11):
            progress.update(1e-4 * i)
        progress.close()
        tty.flush()
        out = _read_all(master)
    finally:
        tty.close()
        os.close(master)
    if expected == "bar":
        assert "\r" in out and "1.000/1.000 simulated ms" in out and "100%" in out
    else:
        assert out.count("transient:") == 10 and "\r\r" not in out.replace("\r\n", "\n")
        assert "transient: 100 % | 1.000/1.000 simulated ms" in out
