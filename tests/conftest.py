import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"
# the motor of the first stator (issue 11), pinned for benches: the tests of the engines' mechanics (kernel, resume,
# active set, seating) run on it, cheap and with values that later stator changes do not move; the shipped motor
# case (the issue-24 stator) has its own tests (tests/test_cases.py, tests/test_motor_preloads.py, test_paraview.py)
PINNED_MOTOR = ROOT / "bench" / "cases" / "wwusm-motor-pinned.toml"
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")
# reduced models (app/reduced/model.py) are cached by their inputs: keep the tests' out of ~/.cache, in one
# place that every rank and subprocess of a run sees
os.environ.setdefault("PIEZODYN_CACHE_DIR", os.path.join(tempfile.gettempdir(), "piezodyn-test-cache"))


def run_cli(*args, mpi: int = 0, timeout: float = 600, cwd=None, kill_at: str | None = None):
    """Run ``python -m app ...`` (optionally under mpirun) and return the CompletedProcess. ``kill_at``:
    PIEZODYN_KILL_AT=<event>:<n>, the run SIGKILLs itself at the n-th <event> (app/killpoint.py)."""
    cmd = [sys.executable, "-m", "app", *map(str, args)]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), *cmd]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", PYTHONPATH=str(ROOT))
    if kill_at is not None:
        env["PIEZODYN_KILL_AT"] = kill_at
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd or ROOT, env=env)


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture
def shared_tmp(tmp_path):
    """A temporary directory that is the same on every MPI rank (rank 0's tmp_path)."""
    from mpi4py import MPI

    return Path(MPI.COMM_WORLD.bcast(str(tmp_path), root=0))


def run_case_quiet(case, out, *overrides):
    from app.runner import run_case

    return run_case(CASES / case if not Path(case).is_absolute() else case, list(overrides), out, quiet=True)


@pytest.fixture
def reduced_builds(monkeypatch, tmp_path):
    """The number of reduced-model builds so far (a list of one count, every call of
    app.reduced.model.build_reduced_model, the one function that builds), the cache in ``tmp_path``."""
    from app.reduced import model

    monkeypatch.setenv("PIEZODYN_CACHE_DIR", str(tmp_path / "cache"))
    count = [0]
    build = model.build_reduced_model

    def counted(*args, **kwargs):
        count[0] += 1
        return build(*args, **kwargs)

    monkeypatch.setattr(model, "build_reduced_model", counted)
    return count
