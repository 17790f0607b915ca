"""A drive locked to the model's resonance (``transient.drive.lock = "resonance"``, app/drive.py locked_case): the
run drives at the tier's own model's resonance nearest ``frequency_Hz`` plus ``detuning_Hz``.

* The arithmetic and the cache: the locked case drives at the mean of the resonances plus the detuning and keeps
  the basis's frequencies (cutoff, enrichment target, damping reference) at the nominal value, so its reduced-model
  cache key is the written case's (else the modal tier would build its stator twice per run).
* The FE tier: the resonance it locks to is the FE modal analysis's short-circuit f_r of the same mesh (the
  reference: app/modal.py run_modal, the same SLEPc shift-invert; tolerance 1e-7 relative, both converge to
  SLEPc's default 1e-8 on the same operator), and the drive frequency is it plus the detuning to round-off.
* The modal tier: a sweep over the detuning builds the reduced model once (counted) and every point drives at the
  reduced model's resonance plus its detuning; with the FE mode in the basis (enrich_modes = 1) that resonance is
  the FE one (Rayleigh-Ritz on a span holding the eigenvector: 1e-6 relative).
"""

from __future__ import annotations

import json

import pytest
from conftest import CASES
from mpi4py import MPI

DRILL = CASES / "usdc-fe.toml"
MOTOR = CASES / "wwusm-motor.toml"
TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "transient.end_time_s=2e-6", "transient.output_interval_s=1e-6", "output.fields=false", "output.plots=false",
        'transient.drive.lock="resonance"', "transient.drive.lock_modes=1"]


def test_the_locked_case_drives_at_the_resonance_plus_the_detuning_and_keeps_its_cache_key():
    from app.case.schema import load_case
    from app.drive import locked_case
    from app.reduced.model import cache_key

    case = load_case(MOTOR, ["transient.drive.detuning_Hz=12.5"])
    locked, record = locked_case(case, [36070.0, 36071.0])
    assert locked.transient.drive.frequency_Hz == pytest.approx(36070.5 + 12.5, rel=1e-15)
    assert record["resonance_Hz"] == pytest.approx(36070.5, rel=1e-15)
    assert record["nominal_frequency_Hz"] == case.transient.drive.frequency_Hz
    assert locked.reduction.cutoff_Hz == pytest.approx(case.reduction.cutoff_factor * 36065.0)
    assert locked.reduction.enrich_near_Hz == 36065.0
    assert cache_key(locked) == cache_key(case)
    # the key still follows what changes the basis: another nominal frequency moves the cutoff and the enrichment
    other = load_case(MOTOR, ["transient.drive.frequency_Hz=36000.0"])
    assert cache_key(other) != cache_key(case)


def _run(tmp_path, name, sets):
    from app.runner import run_case

    return run_case(str(DRILL), TINY + sets, tmp_path / name, quiet=True)


def test_the_fe_tier_locks_to_its_own_modal_resonance(tmp_path):
    from app.runner import run_case

    summary = _run(tmp_path, "fe", ["transient.drive.detuning_Hz=50.0"])
    drive = summary["results"]["transient"]["drive"]
    modal = run_case(str(DRILL), TINY + ['analyses=["modal"]', 'modal.electrical="short"',
                                         f"modal.target_frequency_Hz={drive['nominal_frequency_Hz']}"],
                     tmp_path / "modal", quiet=True)["results"]["modal"]
    nearest = min((m["resonance_Hz"] for m in modal["modes"]), key=lambda f: abs(f - drive["nominal_frequency_Hz"]))
    assert drive["resonance_Hz"] == pytest.approx(nearest, rel=1e-7)
    assert summary["results"]["transient"]["drive_frequency_Hz"] == pytest.approx(drive["resonance_Hz"] + 50.0,
                                                                                  rel=1e-14)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="counts the builds of one process")
def test_a_detuning_sweep_of_the_modal_tier_builds_once_and_follows_the_reduced_resonance(reduced_builds, tmp_path):
    from app.sweep import parse_param, run_sweep

    sets = TINY + ['tier="modal"', "reduction.enrich_modes=1", "damping.material_quality=false"]
    rows = run_sweep(str(DRILL), [parse_param("transient.drive.detuning_Hz=-40.0,0.0,40.0")], tmp_path / "sweep",
                     sets=sets, comm=None, progress=False)
    assert rows is not None and not any("_failed" in r for r in rows), rows
    assert reduced_builds[0] == 1
    drives = []
    for point in sorted((tmp_path / "sweep").glob("*/summary.json")):
        transient = json.loads(point.read_text())["results"]["transient"]
        drive = transient["drive"]
        assert transient["drive_frequency_Hz"] == pytest.approx(drive["resonance_Hz"] + drive["detuning_Hz"],
                                                                rel=1e-14)
        # the enrichment put the FE mode in the basis: the reduced resonance is the FE one
        assert drive["resonance_Hz"] == pytest.approx(transient["reduction"]["enrichment_modes_Hz"][0], rel=1e-6)
        drives.append(drive)
    assert sorted(d["detuning_Hz"] for d in drives) == [-40.0, 0.0, 40.0]
    assert len({round(d["resonance_Hz"], 9) for d in drives}) == 1
