#!/usr/bin/env bash
# The test command: lint, the serial suite, then the MPI suite on 2 ranks.
set -euo pipefail
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
export MPLBACKEND=Agg
# the ParaView checks (tests/test_paraview.py) fail instead of skipping when pvpython or Xvfb is missing
export PIEZODYN_REQUIRE_PARAVIEW="${PIEZODYN_REQUIRE_PARAVIEW:-1}"
PY=.venv/bin/python
if [ -x .venv/bin/ruff ]; then .venv/bin/ruff check app forms geometry tests bench demos; fi
# the serial suite on two pytest-xdist workers, one test file per worker (a file's module fixtures are built once);
# PIEZODYN_TEST_WORKERS=0 runs it in this process
WORKERS="${PIEZODYN_TEST_WORKERS:-2}"
XDIST=(); if [ "$WORKERS" != 0 ]; then XDIST=(-n "$WORKERS" --dist loadfile); fi
$PY -m pytest -q --color=no --with-mpi -m "not slow" "${XDIST[@]}" tests "$@"
mpirun -n 2 -x OPENBLAS_NUM_THREADS=1 $PY -m pytest -q --color=no --with-mpi -m "mpi and not slow" -p no:cacheprovider tests
