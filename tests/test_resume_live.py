"""``--resume`` (or a second ``run``) of a directory a live run is writing is refused with one line before any file
changes (app/loop/loop.py:DirectoryLock, taken by app/runner.py:run_case before anything is written).

The live run is stopped (SIGSTOP) while the second command runs, so the directory's checksums before and after
can only differ by what the second command did; then it is let go and killed."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import CASES, ROOT

SETS = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "output.fields=false", "output.plots=false", "transient.end_time_s=0.05",
        "transient.checkpoint_interval_steps=20"]


def _sets():
    return [a for o in SETS for a in ("--set", o)]


def checksums(directory):
    return {str(p.relative_to(directory)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.fixture
def live_run(tmp_path):
    out = tmp_path / "live"
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    proc = subprocess.Popen([sys.executable, "-m", "app", "run", CASES / "usdc-fe.toml", "--out", out, "--quiet",
                             *_sets()], cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 300
        while not (out / "checkpoint" / "checkpoint.json").exists():       # running, a checkpoint written
            assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "the live run wrote no checkpoint in 300 s"
            time.sleep(0.2)
        proc.send_signal(signal.SIGSTOP)
        time.sleep(0.5)
        yield out
    finally:
        proc.send_signal(signal.SIGCONT)
        proc.kill()
        proc.wait()


@pytest.mark.parametrize("command, mpi", [("--resume", 0), ("--resume", 2), ("--out", 0)])
def test_a_directory_a_live_run_writes_is_refused_untouched(live_run, command, mpi):
    from conftest import run_cli

    before = checksums(live_run)
    refused = run_cli("run", CASES / "usdc-fe.toml", command, live_run, "--quiet", *_sets(), mpi=mpi)
    after = checksums(live_run)
    assert refused.returncode == 2, refused.stderr[-2000:]
    lines = [line for line in refused.stderr.splitlines() if line.startswith("piezodyn: error:")]
    assert len(lines) == 1 and "another piezodyn run is writing this directory" in lines[0], refused.stderr[-2000:]
    assert "Traceback" not in refused.stderr
    assert after == before
