#!/usr/bin/env bash
# The one install script (README commands, .ci/run and the Dockerfile all call it).
# Debian bookworm as root: apt packages, then a venv that sees Debian's dolfinx, then piezodyn.
# Idempotent: apt-get and pip skip what is already there.
#
#   bash .ci/install.sh            both phases (a fresh machine, CI)
#   bash .ci/install.sh packages   apt packages only: needs nothing but this file (the Dockerfile's
#                                  first layer, so a source edit does not reinstall them)
#   bash .ci/install.sh project    the venv and piezodyn in it (needs the source tree)
set -euo pipefail
cd "$(dirname "$0")/.."
phase="${1:-all}"
case "$phase" in
  all|packages|project) ;;
  *) echo "usage: bash .ci/install.sh [all|packages|project]" >&2; exit 2 ;;
esac

install_packages() {
  local PACKAGES=(
    python3-dolfinx-real python3-petsc4py-real python3-slepc4py-real python3-mpi4py openmpi-bin
    python3-gmsh python3-meshio python3-h5py python3-numpy python3-scipy python3-matplotlib
    python3-numba python3-tqdm python3-pytest python3-pytest-mpi python3-pytest-xdist python3-venv python3-pip
    python3-setuptools python3-wheel python3-threadpoolctl libopenblas0-pthread
  )
  # test extras: tests/test_paraview.py opens results with ParaView's own readers (pvpython under
  # Xvfb); the Docker image leaves them out (PIEZODYN_NO_TEST_EXTRAS=1)
  if [ "${PIEZODYN_NO_TEST_EXTRAS:-0}" != 1 ]; then
    PACKAGES+=(paraview python3-paraview xvfb xauth)
  fi
  local missing=() p
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ "${#missing[@]}" -gt 0 ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q
    apt-get install -y -q --no-install-recommends "${missing[@]}"
  fi
}

install_project() {
  # Debian's python, not a pyenv/conda one on PATH: dolfinx lives in Debian's site-packages.
  if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import dolfinx" 2>/dev/null; then
    rm -rf .venv
    /usr/bin/python3 -m venv --system-site-packages .venv
  fi
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
  if [ "${PIEZODYN_NO_LINT:-0}" != 1 ]; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check "ruff>=0.4" || echo "ruff not installed (lint skipped)"
  fi
  .venv/bin/python -c "import dolfinx, app; print(f'piezodyn {app.__version__} on dolfinx {dolfinx.__version__}')"
}

if [ "$phase" != project ]; then install_packages; fi
if [ "$phase" != packages ]; then install_project; fi
