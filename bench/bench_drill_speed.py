"""The drill's cost per simulated ms, FE tier and modal tier side by side in one run (issue 27).

Each tier runs ``cases/usdc-fe.toml`` (default mesh, harmonic start, the downforce ``--force``) with field output
and plots off, in two pieces: to the window's start, then ``--resume``d to its end. The second piece's loop wall
time (the summary's ``wall_time_s``: stepping, series, checkpoints; not the set-up) over the window's simulated
time is the tier's marginal cost [s per simulated ms], the start-up transient and the set-up left out; its CPU time
(``cpu_time_s``, the process's) beside it, which a loaded machine inflates less. Defaults:
the FE tier from 1 to 2 ms, the modal tier from 20 to 100 ms (the issue's windows). Prints both, their ratio, the
steps per simulated ms of each window and the machine's load average before and after each piece.

    .venv/bin/python bench/bench_drill_speed.py [--force 9] [--fe-ms 1,2] [--modal-ms 20,100] [--keep-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "usdc-fe.toml"


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _piece(tier: str, force: float, end_ms: float, out: Path, resume: bool) -> dict:
    settings = [f'tier="{tier}"', f"transient.end_time_s={end_ms * 1e-3!r}", "output.fields=false",
                "output.plots=false", "transient.checkpoint_interval_steps=0",
                f"transient.loads.fe_force_N=[0.0,{-force!r}]"]
    command = [sys.executable, "-m", "app", "run", str(CASE), "--resume" if resume else "--out", str(out), "--quiet"]
    for item in settings:
        command += ["--set", item]
    subprocess.run(command, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return json.loads((out / "summary.json").read_text())["results"]["transient"]


def window(tier: str, force: float, start_ms: float, end_ms: float, out: Path) -> dict:
    """The marginal cost of ``tier`` from ``start_ms`` to ``end_ms``."""
    loads = [_load()]
    first = _piece(tier, force, start_ms, out, resume=False)
    loads.append(_load())
    mark = time.perf_counter()
    second = _piece(tier, force, end_ms, out, resume=True)
    process_wall = time.perf_counter() - mark
    loads.append(_load())
    simulated_ms = (second["simulated_time_s"] - second["resumed_from_s"]) * 1e3
    return {"tier": tier, "window_ms": [start_ms, end_ms], "s_per_ms": second["wall_time_s"] / simulated_ms,
            "cpu_s_per_ms": second["cpu_time_s"] / simulated_ms, "loop_wall_s": second["wall_time_s"],
            "process_wall_s": process_wall,
            "steps_per_ms": (second["steps"] - first["steps"]) / simulated_ms, "loads": loads}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", type=float, default=9.0, help="downforce [N]")
    parser.add_argument("--fe-ms", default="1,2", help="the FE tier's window [ms]")
    parser.add_argument("--modal-ms", default="20,100", help="the modal tier's window [ms]")
    parser.add_argument("--keep-dir", type=Path, default=None, help="keep the run directories here")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = args.keep_dir if args.keep_dir is not None else Path(tmp)
        for tier, span in (("modal", args.modal_ms), ("fe", args.fe_ms)):
            start_ms, end_ms = (float(x) for x in span.split(","))
            out = base / f"{tier}_{args.force:g}N"
            rows.append(window(tier, args.force, start_ms, end_ms, out))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    modal, fe = rows
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} cores, downforce "
          f"{args.force:g} N; load averages (1, 5, 15 min) before, between and after each tier's pieces")
    print("| tier | window [ms] | s per simulated ms | CPU s per simulated ms | steps per ms | loop wall [s] | load |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['tier']} | {r['window_ms'][0]:g}-{r['window_ms'][1]:g} | {r['s_per_ms']:.4g} | "
              f"{r['cpu_s_per_ms']:.4g} | {r['steps_per_ms']:.0f} | {r['loop_wall_s']:.1f} | "
              f"{' / '.join(r['loads'])} |")
    print(f"\nFE / modal: {fe['s_per_ms'] / modal['s_per_ms']:.0f}x")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
