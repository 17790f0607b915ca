"""Checkpoints and ``piezodyn run --resume DIR``: a run split in two equals the run in one go, and a
run killed with SIGKILL leaves a readable time series and a checkpoint it can resume from."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES, ROOT, run_case_quiet, run_cli
from mpi4py import MPI

CASE = "usdc-fe.toml"
TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "output.plots=false"]
END_S = 2e-4


def read_series(path: Path) -> dict[str, np.ndarray]:
    import h5py

    with h5py.File(path, "r") as f:
        return {name: f[name][:] for name in f}


def assert_same_series(a: dict, b: dict, rtol=0.0):
    assert sorted(a) == sorted(b)
    assert a["time_s"].shape == b["time_s"].shape
    for name in a:
        scale = max(float(np.max(np.abs(a[name]))), 1e-300)
        err = float(np.max(np.abs(a[name] - b[name]))) / scale if a[name].size else 0.0
        assert err <= rtol, f"{name}: relative difference {err:.3e}"


@pytest.fixture(scope="module")
def one_go(tmp_path_factory):
    """The reference: the tiny drill scene run to END_S in one go."""
    out = Path(MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp("one_go")), root=0))
    summary = run_case_quiet(CASE, out, *TINY, f"transient.end_time_s={END_S!r}")
    MPI.COMM_WORLD.barrier()
    return out, summary


@pytest.mark.mpi
def test_resume_from_half_time_equals_one_run(one_go, shared_tmp):
    out_ref, summary_ref = one_go
    reference = MPI.COMM_WORLD.bcast(read_series(out_ref / "transient.h5") if MPI.COMM_WORLD.rank == 0 else None)
    # Split at a step the reference run took (a time on its step grid), in the middle of the run.
    t_half = float(reference["time_s"][reference["time_s"].size // 2])
    first = run_case_quiet(CASE, shared_tmp, *TINY, f"transient.end_time_s={t_half!r}")
    assert first["results"]["transient"]["checkpoints_written"] >= 1
    from app.runner import run_case

    second = run_case(CASES / CASE, [*TINY, f"transient.end_time_s={END_S!r}"], shared_tmp, quiet=True,
                      resume=True)
    MPI.COMM_WORLD.barrier()
    if MPI.COMM_WORLD.rank == 0:
        assert_same_series(reference, read_series(shared_tmp / "transient.h5"))
    res_ref, res = summary_ref["results"]["transient"], second["results"]["transient"]
    assert res["resumed_from_s"] == pytest.approx(t_half, rel=1e-15)
    for key in ("steps", "attempts", "cutbacks", "event_refinements", "newton_iterations"):
        assert res[key] == res_ref[key], key
    assert sorted(res["contacts"]) == sorted(res_ref["contacts"])
    for name, ref in res_ref["contacts"].items():
        assert res["contacts"][name] == pytest.approx(ref, rel=1e-12, abs=1e-300), name


def test_resume_of_a_different_case_is_refused(one_go, tmp_path):
    out_ref, _ = one_go
    result = run_cli("run", CASES / CASE, "--resume", out_ref,
                     *[a for o in [*TINY, "transient.drive.frequency_Hz=20000.0"] for a in ("--set", o)])
    assert result.returncode == 2, result.stderr[-2000:]
    assert "transient.drive.frequency_Hz" in result.stderr
    assert "Traceback" not in result.stderr
    empty = run_cli("run", CASES / CASE, "--resume", tmp_path, *[a for o in TINY for a in ("--set", o)])
    assert empty.returncode == 2 and "no checkpoint" in empty.stderr


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="drives a serial subprocess")
def test_killed_run_is_readable_and_resumes_to_the_same_series(one_go, tmp_path):
    import h5py

    out_ref, _ = one_go
    overrides = [*TINY, f"transient.end_time_s={END_S!r}", "transient.checkpoint_interval_steps=10"]
    cmd = [sys.executable, "-m", "app", "run", str(CASES / CASE), "--out", str(tmp_path), "--quiet",
           *[a for o in overrides for a in ("--set", o)]]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    pointer = tmp_path / "checkpoint" / "checkpoint.json"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if pointer.exists() and json.loads(pointer.read_text())["rows"] >= 20:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be killed: " + proc.stderr.read().decode()[-2000:]
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    meta = json.loads(pointer.read_text())
    with h5py.File(tmp_path / "transient.h5", "r") as f:     # readable after SIGKILL
        t = f["time_s"][:]
        assert f["time_s"].attrs["unit"] == "s"
    assert t.size >= meta["rows"] >= 20
    assert np.all(np.diff(t) > 0)
    assert t[meta["rows"] - 1] == meta["t_s"]
    assert meta["t_s"] < END_S
    result = run_cli("run", CASES / CASE, "--resume", tmp_path, "--quiet",
                     *[a for o in overrides for a in ("--set", o)])
    assert result.returncode == 0, result.stderr[-3000:]
    assert_same_series(read_series(out_ref / "transient.h5"), read_series(tmp_path / "transient.h5"))
