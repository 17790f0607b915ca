"""The reduced model's cache (app/reduced/model.py:cache_key): built once over a sweep of what does not change
the basis, again for what does. The builds are counted by wrapping app.reduced.model.build_reduced_model (the
one function that builds), on the tests' tiny drill in the modal tier, with a private cache directory.

* A voltage sweep (the drill's drive is a target tip amplitude, i.e. its voltage) builds once.
* A drive-frequency sweep with the basis pinned (cutoff in Hz, stiffness-proportional damping: no material
  quality factor, whose beta_j = 1 / (omega Q) follows the reference frequency) builds once. Before issue 27 the
  damping's reference frequency was keyed whatever the damping, so this sweep built at every point.
* A sweep over the cutoff (it changes the basis) builds at every point: the count can fail both ways.
"""

from __future__ import annotations

import pytest
from conftest import CASES
from mpi4py import MPI

DRILL = CASES / "usdc-fe.toml"
TINY = ['tier="modal"', "geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "transient.end_time_s=2e-6", "transient.output_interval_s=1e-6", "output.fields=false", "output.plots=false",
        "reduction.cutoff_Hz=80000.0"]


@pytest.fixture
def builds(reduced_builds):
    """The number of reduced-model builds so far (a list of one count), the cache in ``tmp_path`` (conftest.py)."""
    return reduced_builds


def _sweep(tmp_path, name, param, sets=()):
    from app.sweep import parse_param, run_sweep

    rows = run_sweep(str(DRILL), [parse_param(param)], tmp_path / name, sets=TINY + list(sets), comm=None,
                     progress=False)
    assert rows is not None and not any("_failed" in r for r in rows), rows
    return rows


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="counts the builds of one process")
def test_a_voltage_sweep_builds_the_reduced_model_once(builds, tmp_path):
    _sweep(tmp_path, "voltage", "transient.drive.tip_amplitude_m=10e-6,15e-6,20e-6")
    assert builds[0] == 1


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="counts the builds of one process")
def test_a_drive_frequency_sweep_on_a_pinned_basis_builds_once_and_a_cutoff_sweep_every_time(builds, tmp_path):
    _sweep(tmp_path, "frequency", "transient.drive.frequency_Hz=20000.0,20100.0,20200.0",
           ["damping.material_quality=false"])
    assert builds[0] == 1
    _sweep(tmp_path, "cutoff", "reduction.cutoff_Hz=60000.0,70000.0", ["damping.material_quality=false"])
    assert builds[0] == 3
