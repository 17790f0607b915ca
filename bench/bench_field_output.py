"""What field output costs a transient run: the same case with default outputs and with ``output.fields=false``,
one after the other in one invocation, optionally for two piezodyn installations (before / after).

For each (installation, outputs) pair it runs ``piezodyn run CASE --quiet --set output.plots=false [--set ...]``
in a fresh process and reports the process's wall time, the run loop's wall time (``wall_time_s`` of the
summary's transient results), the loop's own timer of the field output (``field_output_wall_s``: writing,
buffering and flushing the frames) and the number of frames, with the load average before and after each
run. Two fractions of the run with default outputs are printed:

- ``timer``: field_output_wall_s / loop wall time of the default-output run;
- ``difference``: (loop wall with fields - loop wall without) / loop wall with fields (the cost of fields
  wherever it lands, e.g. a checkpoint that waits for them).

The same two fractions of the loop's process CPU time (``cpu_time_s``, ``field_output_cpu_s``) are printed when
the installation reports them: on a shared machine the wall times of both runs stretch with the load, the CPU
times much less. Where the modal tier writes its batches on a writer thread (``field_writer_wall_s``, printed per
run as "writer thread"), the timer is what the loop waited for, the thread's work overlapping the stepping, and
the CPU fractions count both threads.

    PIEZODYN_CACHE_DIR=/work/wt/cache OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_field_output.py \\
        cases/usdc-fe.toml --set 'tier="modal"' --set transient.end_time_s=0.05 \\
        [--before /path/to/old/.venv/bin/piezodyn] [--repeat 2]

The reduced model is built (or read from the cache) by a warm-up run first, so every timed run reads it from
the cache. Plots are off in every run (they are drawn after the loop and are not field output).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / ".venv" / "bin" / "piezodyn"


def load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def run(piezodyn: str, case: Path, sets: list[str], out: Path) -> dict:
    cmd = [piezodyn, "run", str(case), "--out", str(out), "--quiet", "--set", "output.plots=false",
           *[a for s in sets for a in ("--set", s)]]
    before = load()
    start = time.perf_counter()
    done = subprocess.run(cmd, cwd=Path(piezodyn).resolve().parents[2], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr[-3000:]}")
    res = json.loads((out / "summary.json").read_text())["results"]["transient"]
    return {"process_s": wall, "loop_s": res["wall_time_s"], "field_s": res.get("field_output_wall_s", 0.0),
            "loop_cpu_s": res.get("cpu_time_s"), "field_cpu_s": res.get("field_output_cpu_s"),
            "writer_s": res.get("field_writer_wall_s"), "writer_cpu_s": res.get("field_writer_cpu_s"),
            "frames": res.get("field_outputs", 0), "steps": res["steps"], "load": f"{before} -> {load()}",
            "from_cache": res.get("reduction", {}).get("from_cache")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", type=Path)
    parser.add_argument("--set", dest="sets", action="append", default=[], help="a case override (repeatable)")
    parser.add_argument("--before", help="a second piezodyn executable, run first (e.g. an older checkout's)")
    parser.add_argument("--repeat", type=int, default=1, help="timed runs of each pair")
    args = parser.parse_args()
    case = args.case.resolve()
    installs = ([("before", args.before)] if args.before else []) + [("after", str(HERE))]
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {load()}")
    print(f"# case {case} --set {' --set '.join(args.sets)}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        run(installs[-1][1], case, [*args.sets, "output.fields=true"], tmp / "warm")      # the cache filled
        for repeat in range(args.repeat):
            for label, piezodyn in installs:
                for outputs, extra in (("default", []), ("fields off", ["output.fields=false"])):
                    r = run(piezodyn, case, [*args.sets, *extra], tmp / f"{label}-{outputs}-{repeat}".replace(" ", "_"))
                    rows.append((label, outputs, r))
                    cpu = (f"  loop cpu {r['loop_cpu_s']:6.2f} s  fields cpu {r['field_cpu_s']:5.2f} s"
                           if r["loop_cpu_s"] is not None else "")
                    if r["writer_s"]:
                        cpu += f"  writer thread {r['writer_s']:5.2f} s (cpu {r['writer_cpu_s'] or 0:5.2f} s)"
                    print(f"{label:6s} {outputs:10s} process {r['process_s']:7.2f} s  loop {r['loop_s']:7.2f} s  "
                          f"fields {r['field_s']:6.2f} s{cpu}  frames {r['frames']:4d}  steps {r['steps']}  "
                          f"cache {r['from_cache']}  load {r['load']}", flush=True)
    print("\n| code | loop, default outputs [s] | loop, fields off [s] | field output (timer) [s] | frames | "
          "fraction (timer) | fraction (difference) | loop CPU, default / off [s] | field CPU [s] | "
          "CPU fraction (timer) | CPU fraction (difference) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for repeat in range(args.repeat):
        for label, _ in installs:
            on = next(r for lab, o, r in rows[repeat * 2 * len(installs):] if lab == label and o == "default")
            off = next(r for lab, o, r in rows[repeat * 2 * len(installs):] if lab == label and o == "fields off")
            cpu = "| - | - | - | - |"
            if on["loop_cpu_s"] is not None and off["loop_cpu_s"] is not None:
                cpu = (f"| {on['loop_cpu_s']:.2f} / {off['loop_cpu_s']:.2f} | {on['field_cpu_s']:.2f} | "
                       f"{on['field_cpu_s'] / on['loop_cpu_s']:.1%} | "
                       f"{(on['loop_cpu_s'] - off['loop_cpu_s']) / on['loop_cpu_s']:.1%} |")
            print(f"| {label} | {on['loop_s']:.2f} | {off['loop_s']:.2f} | {on['field_s']:.2f} | {on['frames']} | "
                  f"{on['field_s'] / on['loop_s']:.1%} | {(on['loop_s'] - off['loop_s']) / on['loop_s']:.1%} {cpu}")


if __name__ == "__main__":
    main()
