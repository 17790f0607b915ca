"""The reduced stator's build (case -> cached reduced model, mesh and assembly included, 1 rank) by phase, for
several builds side by side in one run (issue 27): each a checkout's code (its Python, run with that checkout as the
working directory, so ``python -m app`` imports its ``app``) on a case file, into a fresh empty cache directory, one
after the other (a case-mesh build peaks at several GB: never two at once). Prints each build's phases (the log
line "modal tier: build phases: ..."), its whole wall time, the machine's load before and after, and compares the
cached reduced models with the first one: fixed-interface frequencies, the enrichment (the FE model's own F(1,4)
pair), the reduced short-circuit resonances near the drive, and where the two share the operators (same case and
quadrature), the static block of K_r and M_r (the constraint modes: the same vectors in both bases).

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python bench/bench_reduced_build.py --out DIR \\
        --build old=/work/main:/work/main/cases/wwusm-motor.toml \\
        --build new=.:cases/wwusm-motor.toml [--build LABEL=CHECKOUT:CASE ...] [--set KEY=VALUE ...] \\
        [--options 'LABEL=-reduction_pc_type lu' ...]

A build runs ``CHECKOUT/.venv/bin/python -m app run CASE --set transient.end_time_s=3e-5 --set output.fields=false
--set output.plots=false --out DIR/LABEL`` with PIEZODYN_CACHE_DIR=DIR/LABEL-cache (empty).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["transient.end_time_s=3e-5", "output.fields=false", "output.plots=false"]


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _build(label: str, checkout: Path, case: Path, sets: list[str], out: Path, petsc_options: str = "") -> dict:
    cache = out / f"{label}-cache"
    run_dir = out / label
    if cache.exists() and any(cache.iterdir()):
        sys.exit(f"{cache} is not empty: a build must start from an empty cache")
    cache.mkdir(parents=True, exist_ok=True)
    cmd = [str(checkout / ".venv" / "bin" / "python"), "-m", "app", "run", str(case), "--out", str(run_dir)]
    for item in SHORT + sets:
        cmd += ["--set", item]
    env = dict(os.environ, PIEZODYN_CACHE_DIR=str(cache))
    env.pop("PYTHONPATH", None)
    if petsc_options:
        env["PETSC_OPTIONS"] = petsc_options
    load_before = _load()
    log = out / f"{label}.log"
    start = time.perf_counter()
    with open(log, "w") as sink:
        child = subprocess.Popen(cmd, cwd=checkout, env=env, stdout=sink, stderr=subprocess.STDOUT, text=True)
        # wait4: this child's own resource usage (RUSAGE_CHILDREN's peak would be the largest of all builds so far)
        _, status, usage = os.wait4(child.pid, 0)
    returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    cpu = usage.ru_utime + usage.ru_stime
    peak_GB = usage.ru_maxrss / 2**20          # ru_maxrss: KiB on Linux
    output = log.read_text()
    if returncode != 0:
        sys.exit(f"build {label} failed ({returncode}): see {log}")
    phases = {}
    for marker in ("build phases: ", "reduction phases: "):
        line = next((ln for ln in output.splitlines() if marker in ln), "")
        rest = line.split(marker, 1)[1] if marker in line else ""
        prefix = "  reduction: " if marker.startswith("reduction") else ""
        found = re.findall(r"(.+?) ([0-9]+\.[0-9]+) s(?: \(CPU ([0-9]+\.[0-9]+) s\))?(?:, |$)", rest)
        phases.update({prefix + name: (float(wall), float(cpu) if cpu else None) for name, wall, cpu in found})
    models = sorted(cache.glob("reduced-*.npz"))
    return {"label": label, "checkout": str(checkout), "case": str(case), "command": " ".join(cmd), "wall_s": wall,
            "cpu_s": cpu, "peak_GB": peak_GB, "petsc_options": petsc_options, "load_before": load_before,
            "load_after": _load(), "phases": phases,
            "model": str(models[0]) if models else None, "run_dir": str(run_dir)}


def _numbers(tree, prefix="") -> dict:
    """The numeric leaves of a JSON tree, by path."""
    out = {}
    items = tree.items() if isinstance(tree, dict) else enumerate(tree) if isinstance(tree, list) else ()
    for key, value in items:
        path = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, (dict, list)):
            out.update(_numbers(value, path))
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            out[path] = float(value)
    return out


def _compare(reference: dict, other: dict, same_operators: bool) -> dict:
    sys.path.insert(0, str(ROOT))
    from app.reduced.model import ReducedModel

    a, b = ReducedModel.load(Path(reference["model"])), ReducedModel.load(Path(other["model"]))
    out = {"coordinates": (a.size, b.size)}
    if a.mode_frequencies_Hz.size == b.mode_frequencies_Hz.size:
        out["fixed_interface_max_rel"] = float(np.max(np.abs(b.mode_frequencies_Hz / a.mode_frequencies_Hz - 1)))
    out["enrichment_Hz"] = (a.enrichment_frequencies_Hz.tolist(), b.enrichment_frequencies_Hz.tolist())
    drive = float(np.mean(a.enrichment_frequencies_Hz)) if a.enrichment_frequencies_Hz.size else 36065.0
    out["resonances_near_drive_Hz"] = (a.resonances_Hz(drive).tolist(), b.resonances_Hz(drive).tolist())
    # the short transient after the build (the drive locked to each model's pair, one drive period): its statistics
    first, second = (_numbers(json.loads((Path(r["run_dir"]) / "summary.json").read_text())["results"]["transient"]
                              .get("statistics", {})) for r in (reference, other))
    shared = [k for k in first if k in second and abs(first[k]) > 0]
    worst = max(shared, key=lambda k: abs(second[k] / first[k] - 1), default=None)
    if worst is not None:
        out["transient_statistics_max_rel"] = (worst, first[worst], second[worst],
                                               abs(second[worst] / first[worst] - 1))
    if same_operators and a.size == b.size:
        static = a.n_interface + len(a.inputs)
        for name in ("K", "M"):
            A, B = getattr(a, name)[:static, :static], getattr(b, name)[:static, :static]
            out[f"static_{name}_max_rel"] = float(np.abs(A - B).max() / np.abs(A).max())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--build", action="append", required=True, metavar="LABEL=CHECKOUT:CASE")
    parser.add_argument("--options", action="append", default=[], metavar="LABEL=PETSC_OPTIONS",
                        help="PETSC_OPTIONS for one build (e.g. a solver variant of the same code)")
    parser.add_argument("--set", action="append", default=[], dest="sets", metavar="KEY=VALUE",
                        help="a case override for every build")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for spec in args.build:
        label, rest = spec.split("=", 1)
        checkout, case = rest.split(":", 1)
        checkout = Path(checkout).resolve()
        case = Path(case) if Path(case).is_absolute() else (Path.cwd() / case).resolve()
        print(f"[{label}] building: {checkout} {case} (load {_load()})", flush=True)
        options = dict(item.split("=", 1) for item in args.options)
        result = _build(label, checkout, case, args.sets, args.out, options.get(label, ""))
        results.append(result)
        print(f"[{label}] {result['wall_s']:.1f} s ({result['cpu_s']:.1f} s CPU), peak {result['peak_GB']:.2f} GB, "
              f"load {result['load_before']} -> {result['load_after']}: "
              + ", ".join(f"{k} {v[0]:.1f} s" for k, v in result["phases"].items()), flush=True)
    names = []                       # in order of appearance: the build's phases, then the reduction's
    for r in results:
        names += [k for k in r["phases"] if k not in names and not k.startswith("  ")]
    for r in results:
        names += [k for k in r["phases"] if k not in names]
    print("\n| phase: wall (CPU) [s] | " + " | ".join(r["label"] for r in results) + " |")
    print("|---|" + "---|" * len(results))
    for name in names + ["total (phases)", "process wall", "process CPU (user + sys)"]:
        cells = []
        for r in results:
            if name == "total (phases)":
                top = [v for k, v in r["phases"].items() if not k.startswith("  ")]
                value = (sum(w for w, _ in top), sum(c for _, c in top) if all(c is not None for _, c in top) else None)
            elif name == "process wall":
                value = (r["wall_s"], None)
            elif name == "process CPU (user + sys)":
                value = (r["cpu_s"], None)
            else:
                value = r["phases"].get(name)
            cells.append("" if value is None else f"{value[0]:.1f}" + (f" ({value[1]:.1f})" if value[1] is not None
                                                                         else ""))
        print(f"| {name} | " + " | ".join(cells) + " |")
    print("| peak memory (the build's process) [GB] | " + " | ".join(f"{r['peak_GB']:.2f}" for r in results) + " |")
    print("| load (1 min) before -> after | " + " | ".join(f"{r['load_before'].split()[0]} -> "
                                                          f"{r['load_after'].split()[0]}" for r in results) + " |")
    for r in results[1:]:
        same = Path(r["case"]).read_text() == Path(results[0]["case"]).read_text()
        r["against_first"] = _compare(results[0], r, same)
        print(f"\n{r['label']} against {results[0]['label']}: {json.dumps(r['against_first'])}")
    (args.out / "builds.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
