"""Every demo in demos/ runs as documented and shows what its docstring says: serially as a script
(``python demos/demo_X.py``, which exits non-zero if the result disagrees with its closed form or
expectation), and on 2 MPI ranks in the MPI suite (``main(COMM_WORLD)`` and ``check``)."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import pytest
from conftest import ROOT
from mpi4py import MPI

DEMOS = sorted(p.stem for p in (ROOT / "demos").glob("demo_*.py"))


def test_every_demo_is_documented_and_runnable():
    assert DEMOS, "no demos found"
    for name in DEMOS:
        module = importlib.import_module(f"demos.{name}")
        assert module.__doc__ and f"python demos/{name}.py" in module.__doc__, name
        assert callable(module.main) and callable(module.check), name


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts serial subprocesses")
@pytest.mark.parametrize("name", DEMOS)
def test_demo_runs_as_a_serial_script(name, tmp_path):
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, str(ROOT / "demos" / f"{name}.py")], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path, env=env)     # from another directory, as a user would
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip(), "a demo prints what it shows"


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="the serial run is the script test above")
@pytest.mark.parametrize("name", DEMOS)
def test_demo_on_two_ranks(name):
    module = importlib.import_module(f"demos.{name}")
    module.check(module.main(MPI.COMM_WORLD))
