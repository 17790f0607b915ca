"""Steady-state start (drill paper: modal -> harmonic -> initial conditions): from the harmonic
state the free transducer keeps its amplitude over 20 cycles, from rest it only rings up."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_case_quiet
from mpi4py import MPI

FREQUENCY_HZ = 20100.0
CYCLES = 20
TARGET_M = 15e-6
FREE = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "output.plots=false", f"transient.end_time_s={CYCLES / FREQUENCY_HZ!r}", "transient.bodies=[]",
        "transient.contacts=[]", "transient.loads.gravity_m_per_s2=[0.0, 0.0]"]


def cycle_amplitudes(out) -> np.ndarray:
    """Half the peak-to-peak tip displacement [m] in each drive cycle (50 samples per cycle)."""
    import h5py

    with h5py.File(out / "transient.h5", "r") as f:
        t, u = f["time_s"][:], f["tip_displacement_m"][:]
    cycle = np.minimum(np.floor(t * FREQUENCY_HZ + 1e-9).astype(int), CYCLES - 1)
    return np.array([0.5 * np.ptp(u[cycle == k]) for k in range(CYCLES)])


@pytest.mark.mpi
@pytest.mark.parametrize("start", ["harmonic", "rest"])
def test_free_transducer_from_harmonic_state_stays_from_rest_rings_up(start, shared_tmp):
    run_case_quiet("usdc-fe.toml", shared_tmp, *FREE, f'transient.initial_state="{start}"')
    if MPI.COMM_WORLD.rank != 0:
        return
    amp = cycle_amplitudes(shared_tmp)
    if start == "harmonic":
        assert amp[0] == pytest.approx(TARGET_M, rel=0.01)
        drift = np.max(np.abs(amp / amp[0] - 1))
        assert drift < 0.01, f"amplitude drifts by {drift:.2%} over {CYCLES} cycles"
    else:
        assert amp[0] < 0.05 * TARGET_M                 # the drive starts the motion from zero ...
        assert amp[-1] > 10 * amp[0]                    # ... and the amplitude builds up,
        assert amp[-1] < 0.5 * TARGET_M                 # far from steady after 20 cycles (high Q)
        assert np.all(np.diff(amp[2:]) > 0)
