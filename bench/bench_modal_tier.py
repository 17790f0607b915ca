"""Modal tier vs FE tier on the drill scene (cases/usdc-fe.toml), same case, one run each.

Reports, for the FE tier and for the modal tier at several basis cutoffs (multiples of the drive
frequency): the basis size, the set-up time (mesh, assembly, reduction, harmonic start), the time
loop's wall time per simulated ms, the speed-up over the FE tier, and the error of the first 20
contact closings against the FE tier (event times; the motion is chaotic later, so longer windows
are compared by statistics, bench/bench_tiers.py). This is the work-precision table of the README.

    .venv/bin/python bench/bench_modal_tier.py [--ms 5] [--factors 5,10,20,40]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "usdc-fe.toml"


def _run(out: Path, *sets: str) -> tuple[dict, float]:
    cmd = [sys.executable, "-m", "app", "run", str(CASE), "--out", str(out), "--quiet",
           "--set", "output.fields=false", "--set", "output.plots=false",
           # a checkpoint at the end only: the loop's speed, not the fsyncs (both tiers alike)
           "--set", "transient.checkpoint_interval_steps=0", *[a for s in sets for a in ("--set", s)]]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return json.loads((out / "summary.json").read_text()), time.perf_counter() - start


def _closings(path: Path) -> list[tuple[float, str]]:
    with h5py.File(path, "r") as f:
        t = f["time_s"][:]
        events = []
        for name in ("tip_ball", "ball_stem", "stem_rock"):
            rows = np.flatnonzero(np.diff(np.concatenate([[0], f[f"{name}_closed"][:]])) == 1)
            events += [(float(t[i]), name) for i in rows if i > 0]
    return sorted(events)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ms", type=float, default=5.0, help="simulated time [ms]")
    parser.add_argument("--factors", default="5,10,20,40", help="basis cutoffs, multiples of the drive frequency")
    args = parser.parse_args()
    end = f"transient.end_time_s={args.ms * 1e-3}"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        fe, fe_total = _run(tmp / "fe", end)
        reference = _closings(tmp / "fe" / "transient.h5")
        fe_loop = fe["results"]["transient"]["wall_s_per_simulated_ms"]
        rows = [("FE", fe["dofs"]["total"], fe_total - fe_loop * args.ms, fe_loop, 1.0, 0.0,
                 len(reference))]
        for factor in [float(f) for f in args.factors.split(",")]:
            modal, total = _run(tmp / f"modal{factor:g}", end, 'tier="modal"', f"reduction.cutoff_factor={factor}")
            tr = modal["results"]["transient"]
            events = _closings(tmp / f"modal{factor:g}" / "transient.h5")
            n = min(20, len(events), len(reference))
            same = [a[1] == b[1] for a, b in zip(events[:n], reference[:n])]
            first_bad = same.index(False) if not all(same) else n
            error = max(abs(a[0] - b[0]) for a, b in zip(events[:first_bad], reference[:first_bad])) if first_bad else 0
            rows.append((f"modal {factor:g} f_drive ({tr['reduction']['modes']} modes)", tr["reduction"]["size"],
                         total - tr["wall_s_per_simulated_ms"] * args.ms, tr["wall_s_per_simulated_ms"],
                         fe_loop / tr["wall_s_per_simulated_ms"], error, first_bad))
    load = open("/proc/loadavg").read().split()[0]
    print(f"# drill scene, {args.ms:g} ms, {platform.node()} ({platform.processor() or platform.machine()}), "
          f"load {load}, {time.strftime('%Y-%m-%d')}")
    print("| tier | unknowns | set-up s | loop s per simulated ms | speed-up | max event-time error (first 20) | "
          "events in order |")
    print("|---|---|---|---|---|---|---|")
    for name, size, setup, per_ms, ratio, error, agree in rows:
        print(f"| {name} | {size} | {setup:.1f} | {per_ms:.4f} | {ratio:.0f}x | {error * 1e6:.3f} us | {agree} |")


if __name__ == "__main__":
    main()
