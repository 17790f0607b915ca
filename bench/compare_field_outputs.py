"""Compare the field output of two runs dataset by dataset (e.g. main's and a branch's of the same case): the same
files, the same XML bytes, in every HDF5 file the same objects, shapes, dtypes and attributes, and per dataset
group (``displacement`` for all its ``step_<k>``, ...) the worst max|a - b| / max|a| over its datasets; the frames'
peaks (``region_peaks_json``) value by value, relative.

    .venv/bin/python bench/compare_field_outputs.py RUN_A RUN_B     (output directories of `piezodyn run`)
"""

from __future__ import annotations

import filecmp
import json
import sys
from pathlib import Path

import h5py
import numpy as np


def outputs(root: Path) -> list[Path]:
    return sorted(p.relative_to(root) for p in root.rglob("*")
                  if p.is_file() and p.suffix in (".h5", ".xdmf") and "checkpoint" not in p.parts)


def compare(a_dir: Path, b_dir: Path) -> dict[str, float]:
    files = outputs(a_dir)
    if files != outputs(b_dir):
        sys.exit(f"different files: {set(files) ^ set(outputs(b_dir))}")
    worst: dict[str, float] = {}
    datasets = 0
    for rel in files:
        if rel.suffix == ".xdmf":
            if not filecmp.cmp(a_dir / rel, b_dir / rel, shallow=False):
                sys.exit(f"{rel}: the XML differs")
            continue
        with h5py.File(a_dir / rel, "r") as fa, h5py.File(b_dir / rel, "r") as fb:
            names_a, names_b = [], []
            fa.visit(names_a.append)
            fb.visit(names_b.append)
            if names_a != names_b:
                sys.exit(f"{rel}: different objects {set(names_a) ^ set(names_b)}")
            for name in ["/", *names_a]:
                oa, ob = fa[name], fb[name]
                if sorted(oa.attrs) != sorted(ob.attrs):
                    sys.exit(f"{rel}:{name}: different attributes")
                for key in oa.attrs:
                    if key == "region_peaks_json":
                        pa, pb = json.loads(oa.attrs[key]), json.loads(ob.attrs[key])
                        if [(s, r, list(v)) for s in pa for r, v in pa[s].items()] != \
                                [(s, r, list(v)) for s in pb for r, v in pb[s].items()]:
                            sys.exit(f"{rel}: different peak keys")
                        d = max(abs(pa[s][r][q] - pb[s][r][q]) / max(abs(pa[s][r][q]), 1e-300)
                                for s in pa for r in pa[s] for q in pa[s][r])
                        worst["region_peaks_json (relative, per value)"] = max(
                            worst.get("region_peaks_json (relative, per value)", 0.0), d)
                    elif not np.array_equal(oa.attrs[key], ob.attrs[key]):
                        sys.exit(f"{rel}:{name}: attribute {key} differs")
                if isinstance(oa, h5py.Dataset):
                    datasets += 1
                    if oa.shape != ob.shape or oa.dtype != ob.dtype:
                        sys.exit(f"{rel}:{name}: shape or dtype differs")
                    x, y = oa[()], ob[()]
                    group = name.rsplit("/", 1)[0] if "/step_" in name else name
                    scale = float(np.abs(x).max()) if x.size else 0.0
                    diff = float(np.abs(x - y).max()) if x.size else 0.0
                    worst[group] = max(worst.get(group, 0.0), diff / scale if scale else diff)
    print(f"{len(files)} files, {datasets} datasets: the same names, shapes, dtypes, attributes; XML identical")
    return worst


def main() -> None:
    worst = compare(Path(sys.argv[1]), Path(sys.argv[2]))
    for name, value in sorted(worst.items(), key=lambda kv: (-kv[1], kv[0])):
        print(f"  {name:45s} worst max|a - b| / max|a| = {value:.1e}")


if __name__ == "__main__":
    main()
