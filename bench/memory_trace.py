"""A command's resident memory over time: runs it, samples its RSS (/proc/PID/status VmRSS, the process itself, not
its children) every ``--every`` seconds, and prints each line of its output prefixed with the elapsed time and the
highest RSS since the previous line, so a build's log shows what each phase holds (BENCHMARKS.md, "the reduced
stator's build memory"). ``--trace FILE`` gets every sample (seconds, GB).

    .venv/bin/python bench/memory_trace.py [--trace FILE] -- .venv/bin/python -m app run CASE --set ...
"""

from __future__ import annotations

import argparse
import subprocess
import threading
import time
from pathlib import Path


def _rss_GB(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 2**20          # kB
    except OSError:
        pass
    return 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=float, default=0.5, help="seconds between samples")
    parser.add_argument("--trace", type=Path, help="write every sample here: seconds, GB")
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    start = time.time()
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    samples: list[tuple[float, float]] = []
    high = [0.0]

    def sample() -> None:
        while child.poll() is None:
            rss = _rss_GB(child.pid)
            samples.append((time.time() - start, rss))
            high[0] = max(high[0], rss)
            time.sleep(args.every)

    threading.Thread(target=sample, daemon=True).start()
    for line in child.stdout:
        print(f"{time.time() - start:7.1f} s, high {high[0]:6.2f} GB | {line.rstrip()}", flush=True)
        high[0] = _rss_GB(child.pid)
    child.wait()
    if args.trace:
        args.trace.write_text("".join(f"{t:.1f} {r:.3f}\n" for t, r in samples))
    print(f"peak {max((r for _, r in samples), default=0.0):.2f} GB, exit {child.returncode}")
    raise SystemExit(child.returncode)


if __name__ == "__main__":
    main()
