"""Every case file under cases/ runs at tiny resolution, serially and on 2 MPI ranks.

A new case file needs an entry in TINY: the overrides that make it run in seconds.
"""

import json

import pytest
from conftest import CASES, run_cli

LUMPED_TINY = ["lumped.duration_s=0.005", "lumped.output.plots=false"]
TINY = {
    "usdc-lumped.toml": LUMPED_TINY,
    "usdc-lumped-fe-scene.toml": LUMPED_TINY,
    "usdc-lumped-0N.toml": LUMPED_TINY,
    "usdc-lumped-3N.toml": LUMPED_TINY,
    "usdc-lumped-6N.toml": LUMPED_TINY,
    "usdc-lumped-9N.toml": LUMPED_TINY,
    "usdc-lumped-0N-1s.toml": LUMPED_TINY,
    "usdc-lumped-3N-1s.toml": LUMPED_TINY,
    "usdc-lumped-6N-1s.toml": LUMPED_TINY,
    "usdc-lumped-9N-1s.toml": LUMPED_TINY,
    "usdc-transducer.toml": ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
                             "harmonic.n_points=5", "harmonic.refine_extrema=false", "modal.n_modes=2"],
    "usdc-fe.toml": ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
                     "transient.end_time_s=2e-4"],
    "validation/pzt4-bar-axisymmetric.toml": ["geometry.parameters.axial_divisions=8", "harmonic.n_points=5"],
    "validation/pzt4-bar-3d.toml": ["geometry.parameters.axial_divisions=8", "geometry.parameters.lateral_divisions=1"],
    "validation/pzt4-disc.toml": ["geometry.parameters.radial_divisions=10", "harmonic.n_points=5"],
    "validation/pzt4-ring-axisymmetric.toml": ["geometry.parameters.mesh_size_m=0.0005"],
    "validation/pzt4-ring-3d.toml": ["geometry.parameters.mesh_size_m=0.002", "modal.n_modes=4"],
    "validation/pzt4-strip-plane-strain.toml": ["geometry.parameters.axial_divisions=8"],
    "validation/strip-friction-drive.toml": ["transient.end_time_s=2.5e-5", "transient.output_interval_s=2.5e-5"],
    "validation/ring-inplane-3d.toml": ["geometry.parameters.mesh_size_m=0.002", "modal.n_modes=4"],
    "validation/ring-inplane-fourier.toml": ["geometry.parameters.mesh_size_m=0.0004"],
    # tests/test_motor_preloads.py's coarse stator (one reduced model in the tests' cache for both)
    "wwusm-motor.toml": ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
                         "reduction.interface_nodes=32", "transient.contacts[0].sample_points=128",
                         "transient.end_time_s=2.8e-4"],
    "wwusm-motor-lumped.toml": ["lumped.curve_points=3"],
    "wwusm-stator-fourier.toml": ["geometry.parameters.mesh_size_m=0.004",
                                  "geometry.parameters.tip_mesh_size_m=0.002"],
    "wwusm-stator.toml": ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.tip_mesh_size_m=0.002",
                          "harmonic.n_points=2", "harmonic.wave.animation_frames=2",
                          # the coarse faceted cylinder sags (one 4 mm layer per 20.5 deg segment: 0.22 mm at the
                          # outer wall): sample further inside
                          "modal.identify.line_radius_m=0.0132", "modal.identify.circle_radius_m=0.01305",
                          "harmonic.wave.circle_radius_m=0.01305"],
}


def all_cases():
    return sorted(str(p.relative_to(CASES)) for p in CASES.rglob("*.toml"))


def test_every_case_has_a_tiny_variant():
    missing = [c for c in all_cases() if c not in TINY]
    assert not missing, f"add tiny-resolution overrides for {missing} to tests/test_cases.py"


#: cases whose 2-rank run is covered by a dedicated two-rank test, so its smoke run goes to the slow suite:
#: the stator's modal analysis (tests/test_stator.py::test_stator_modal_two_ranks_equal_serial) and its two-phase
#: harmonic drive (tests/test_harmonic_phases.py, marked mpi) on the same coarse mesh
TWO_RANKS_COVERED_ELSEWHERE = {"wwusm-stator.toml"}


def _case_params():
    for case in sorted(TINY):
        for ranks, rank_id in ((0, "serial"), (2, "mpi2")):
            slow = ranks and case in TWO_RANKS_COVERED_ELSEWHERE
            yield pytest.param(case, ranks, id=f"{case}-{rank_id}", marks=[pytest.mark.slow] if slow else [])


@pytest.mark.parametrize("case, ranks", list(_case_params()))
def test_case_runs(case, ranks, tmp_path):
    overrides = [arg for o in TINY[case] for arg in ("--set", o)]
    result = run_cli("run", CASES / case, "--out", tmp_path, *overrides, mpi=ranks)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["mpi_size"] == max(ranks, 1)
    assert summary["results"]
    for name in summary.get("outputs", []):
        assert (tmp_path / name).is_file(), f"summary lists {name} but it was not written"
    assert "Traceback" not in result.stderr
