"""Mesh study of the stator's F(1,4): runs a case at a series of `geometry.parameters.mesh_refinement` values
(every mesh size of the stator builder divided by it: profile, tip, arc), one process per mesh, and reports per
mesh the DOFs, the F(1,4) pair, the wall time, the peak memory and the machine load; then, for every three
consecutive meshes, the observed order, the Richardson-extrapolated value and the grid-convergence index of
the finest (Roache; the procedure of Celik et al., J. Fluids Eng. 130 (2008) 078001, with the representative
size h = DOFs^(-1/d), d = 3 for a 3D mesh and 2 for a Fourier model).

    .venv/bin/python bench/bench_stator_mesh.py cases/wwusm-stator.toml --refinements 1 1.26 1.587 2 \
        --out results/mesh-study-3d [--set KEY=VALUE ...]
    .venv/bin/python bench/bench_stator_mesh.py cases/wwusm-stator-fourier.toml --refinements 1 1.5 2.25 3.375

A finished mesh (its summary.json in OUT/r<refinement>/) is not run again, so a study can be extended or
resumed. Results: OUT/study.json and a markdown table on stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load() -> float:
    return os.getloadavg()[0]


def run_mesh(case: Path, refinement: float, out: Path, overrides: list[str]) -> dict:
    """One mesh in its own process (its peak memory is its own): the summary plus wall, memory and load."""
    summary = out / "summary.json"
    meta = out / "run.json"
    if summary.is_file() and meta.is_file():
        return {**json.loads(meta.read_text()), "summary": json.loads(summary.read_text())}
    sets = [f"geometry.parameters.mesh_refinement={refinement}", "output.fields=false", "output.plots=false",
            *overrides]
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "app", "run", str(case), "--out", str(out), "--quiet"]
    cmd += [a for s in sets for a in ("--set", s)]
    load_before = load()
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"mesh refinement {refinement} failed:\n{proc.stderr[-3000:]}")
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    info = {"refinement": refinement, "wall_s": wall, "peak_rss_GB": int(rss.group(1)) / 2**20 if rss else None,
            "load_before": load_before, "load_after": load(), "command": " ".join(cmd[2:])}
    meta.write_text(json.dumps(info, indent=1))
    return {**info, "summary": json.loads(summary.read_text())}


def working_pair(summary: dict) -> tuple[float, float | None]:
    """F(1,4) and its partner [Hz] (the partner is None for a Fourier model: its mode is the pair)."""
    modal = summary["results"]["modal"]
    f = modal["working_resonance_Hz"]
    split = modal.get("working_partner_split_Hz")
    return f, (f + split if split else None)


def observed(h: list[float], phi: list[float]) -> dict:
    """Celik et al. (2008) for meshes 1 (finest), 2, 3 of sizes h and values phi: order p, extrapolated value,
    relative extrapolated error and GCI of the finest mesh (safety factor 1.25)."""
    (h1, h2, h3), (f1, f2, f3) = h, phi
    r21, r32 = h2 / h1, h3 / h2
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0 or e32 == 0:
        return {"order": None, "note": "two meshes give the same value"}
    s = math.copysign(1.0, e32 / e21)
    p = 2.0
    for _ in range(200):
        q = math.log((r21**p - s) / (r32**p - s))
        p_new = abs(math.log(abs(e32 / e21)) + q) / math.log(r21)
        if abs(p_new - p) < 1e-12:
            break
        p = p_new
    extrapolated = (r21**p * f1 - f2) / (r21**p - 1)
    e_a = abs((f1 - f2) / f1)
    return {"order": p, "oscillating": s < 0, "r21": r21, "r32": r32, "extrapolated_Hz": extrapolated,
            "extrapolated_error": abs((extrapolated - f1) / extrapolated), "gci_fine": 1.25 * e_a / (r21**p - 1)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("case")
    parser.add_argument("--refinements", type=float, nargs="+", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    args = parser.parse_args(argv)
    case, out = Path(args.case).resolve(), Path(args.out)
    rows = []
    for refinement in sorted(args.refinements):
        run = run_mesh(case, refinement, out / f"r{refinement:g}", args.overrides)
        s = run["summary"]
        f, partner = working_pair(s)
        rows.append({"refinement": refinement, "dofs": s["dofs"]["total"], "cells": s["dofs"]["cells"],
                     "f_Hz": f, "partner_Hz": partner, "wall_s": run["wall_s"], "peak_rss_GB": run["peak_rss_GB"],
                     "load": 0.5 * (run["load_before"] + run["load_after"]), "phases_s": s["wall_time_s"]})
        print(f"refinement {refinement:g}: {rows[-1]['dofs']} DOFs, F(1,4) {f:.2f} Hz", file=sys.stderr, flush=True)
    dim = 2 if rows[0]["cells"] and json.loads((out / f"r{rows[0]['refinement']:g}" / "summary.json")
                                                .read_text())["case"]["geometry"]["model"] == "fourier" else 3
    for row in rows:
        row["h"] = row["dofs"] ** (-1.0 / dim)
    triplets = []
    fine_first = rows[::-1]
    for k in range(len(fine_first) - 2):
        trio = fine_first[k:k + 3]
        triplets.append({"refinements": [r["refinement"] for r in trio],
                         **observed([r["h"] for r in trio], [r["f_Hz"] for r in trio])})
    (out / "study.json").write_text(json.dumps({"case": str(args.case), "overrides": args.overrides, "meshes": rows,
                                                "triplets": triplets, "dimension": dim}, indent=1))
    print("| refinement | DOFs | F(1,4) pair [Hz] | wall [s] | peak memory [GB] | load |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        pair = f"{r['f_Hz']:.2f}" + (f" / {r['partner_Hz']:.2f}" if r["partner_Hz"] else "")
        print(f"| {r['refinement']:g} | {r['dofs']} | {pair} | {r['wall_s']:.0f} | "
              f"{r['peak_rss_GB'] or float('nan'):.2f} | {r['load']:.1f} |")
    print()
    print("| meshes (refinement) | r21, r32 | observed order p | extrapolated F(1,4) [Hz] | GCI fine [%] |")
    print("|---|---|---|---|---|")
    for t in triplets:
        if t.get("order") is None:
            print(f"| {t['refinements']} | - | - | - | {t.get('note')} |")
            continue
        print(f"| {', '.join(f'{x:g}' for x in t['refinements'])} | {t['r21']:.3f}, {t['r32']:.3f} | "
              f"{t['order']:.2f}{' (oscillating)' if t['oscillating'] else ''} | {t['extrapolated_Hz']:.2f} | "
              f"{100 * t['gci_fine']:.4f} |")


if __name__ == "__main__":
    main()
