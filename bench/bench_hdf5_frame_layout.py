"""What the HDF5 file of a batch of field frames costs, and what part of it is the layout: app/files.py
``write_h5_atomic`` (the field output's writer) on a drill batch (64 frames of 971 vertices: displacement (n, 3),
potential (n,), von Mises (n,), principal stresses (n, 3), E (n, 3), and the bodies' 66 vertices (66, 3), plus
``time_s`` and ``step``) in three shapes, alternated in one process, best CPU time of ``--repeat`` each:

- ``per frame``: the files' layout, a dataset per field and frame (``<field>/step_<k>``), 386 datasets;
- ``per frame, 1 value``: the same 386 datasets of one row each (what the datasets cost without their bytes);
- ``per field``: the same bytes as one (frames, n, k) dataset per field, 8 datasets (what the bytes cost: a
  layout meshio 5.0.0's XDMF reader cannot read frame by frame, see BENCHMARKS.md "Field output of a modal run").

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python bench/bench_hdf5_frame_layout.py [--repeat 12]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from app.files import write_h5_atomic  # noqa: E402

FRAMES, VERTICES, BODY_VERTICES = 64, 971, 66
FIELDS = {"displacement": (VERTICES, 3), "potential": (VERTICES,), "von_mises_Pa": (VERTICES,),
          "principal_stress_Pa": (VERTICES, 3), "electric_field_V_per_m": (VERTICES, 3),
          "bodies/displacement": (BODY_VERTICES, 3)}


def batches(rng) -> dict[str, dict]:
    index = {"time_s": np.arange(FRAMES) * 1e-4, "step": np.arange(FRAMES, dtype=np.int64)}
    whole = {name: rng.standard_normal((FRAMES, *shape)) for name, shape in FIELDS.items()}
    per_frame = {**index, **{f"{name}/step_{k:06d}": values[k] for name, values in whole.items()
                             for k in range(FRAMES)}}
    one_value = {**index, **{f"{name}/step_{k:06d}": values[k][:1] for name, values in whole.items()
                             for k in range(FRAMES)}}
    return {"per frame": per_frame, "per frame, 1 value": one_value, "per field": {**index, **whole}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=12)
    args = parser.parse_args()
    shapes = batches(np.random.default_rng(0))
    best = dict.fromkeys(shapes, np.inf)
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            for label, datasets in shapes.items():
                cpu = time.process_time()
                write_h5_atomic(Path(tmp) / "batch.h5", datasets, {"displacement": {"units": "m"}})
                best[label] = min(best[label], time.process_time() - cpu)
    for label, datasets in shapes.items():
        mb = sum(v.nbytes for v in datasets.values()) / 1e6
        print(f"{label:20s} {len(datasets):4d} datasets {mb:5.2f} MB: {1e3 * best[label]:6.2f} ms CPU per batch "
              f"({1e6 * best[label] / FRAMES:5.1f} us per frame)")


if __name__ == "__main__":
    main()
