"""Compare two transient time series (``transient.h5``) of the same case: step by step, every dataset.

Two runs of one case by two versions of the solver take the same steps when their contact sets change at the
same steps; then each dataset's largest difference, relative to its largest magnitude, says how far the versions
agree. Each step's Newton iteration stops at 1e-10 of its force scale (app/transient/coupled.py), so versions
that differ in round-off only (another LU, another summation order) agree to ~1e-10 per step, growing slowly
along the run.

    .venv/bin/python bench/compare_series.py RUN_A/transient.h5 RUN_B/transient.h5 [--skip-prefix X ...]
"""

from __future__ import annotations

import argparse
import json

import h5py
import numpy as np


def compare(path_a, path_b, skip=()) -> dict:
    with h5py.File(path_a, "r") as a, h5py.File(path_b, "r") as b:
        n_a, n_b = a["time_s"].shape[0], b["time_s"].shape[0]
        n = min(n_a, n_b)
        out = {"rows": [n_a, n_b], "same_times": bool(np.allclose(a["time_s"][:n], b["time_s"][:n], rtol=1e-12,
                                                                  atol=0.0)),
               "datasets": {}}
        for key in sorted(set(a) & set(b)):
            if not isinstance(a[key], h5py.Dataset) or any(key.startswith(p) for p in skip):
                continue
            x, y = np.asarray(a[key][:n], dtype=float), np.asarray(b[key][:n], dtype=float)
            scale = float(np.max(np.abs(y))) if y.size else 0.0
            diff = float(np.max(np.abs(x - y))) if y.size else 0.0
            out["datasets"][key] = {"max_abs_difference": diff, "largest_value": scale,
                                    "relative": diff / scale if scale > 0 else (0.0 if diff == 0 else float("inf"))}
    out["worst_relative"] = max((d["relative"] for d in out["datasets"].values()), default=0.0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--skip-prefix", nargs="*", default=[], help="datasets to leave out")
    args = parser.parse_args()
    result = compare(args.a, args.b, args.skip_prefix)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
