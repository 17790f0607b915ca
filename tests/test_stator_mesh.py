"""The stator's swept meshes, their one-sector cyclic model, and the 3D model against the Fourier-harmonic one.

References: the whole 3D mesh (a sector with cyclic constraints must give its F(1,4) exactly: the whole mesh is
the sector repeated); the 2D Fourier model of order 4 on the same profile mesh, exact in theta (the 3D model
must approach it as the layers round the circumference are refined, at the order of its theta error)."""

import pytest
from conftest import run_case_quiet

SECTOR = "validation/wwusm-stator-sector.toml"
FOURIER = "wwusm-stator-fourier.toml"
COARSE = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.tip_mesh_size_m=0.002",
          "output.fields=false", "output.plots=false"]


def f14(summary) -> float:
    return summary["results"]["modal"]["working_resonance_Hz"]


def test_one_sector_gives_the_whole_mesh_f14(tmp_path):
    """The sector (one 22.5 deg pitch, cyclic harmonic 4) and the whole swept mesh (16 pitches): the same
    discrete problem, so the same F(1,4) to the eigensolver's tolerance; the whole mesh's pair is degenerate
    (the mesh is invariant under the pitch's rotation, and every electrode is grounded)."""
    layers = ["geometry.parameters.arc_mesh_size_m=0.004"]
    sector = f14(run_case_quiet(SECTOR, tmp_path / "sector", *COARSE, *layers))
    whole = run_case_quiet(SECTOR, tmp_path / "whole", *COARSE, *layers, "geometry.parameters.sector_deg=nan",
                           "modal.cyclic=nan", "modal.n_modes=6")
    modal = whole["results"]["modal"]
    assert sector == pytest.approx(f14(whole), rel=1e-8)
    split = [m["resonance_Hz"] for m in modal["modes"]]
    pair = sorted(split, key=lambda f: abs(f - sector))[:2]
    assert abs(pair[1] - pair[0]) < 1e-6 * sector


def test_three_d_approaches_the_fourier_model_on_the_same_profile(tmp_path):
    """With a full outer electrode (as the Fourier model has) the 3D sector on the Fourier model's profile mesh
    differs from it only by the discretisation round the circumference: halving the layers' length divides the
    difference by 3 to 5 (second order), and with 0.3 mm layers it is below 0.03 %."""
    profile = ["geometry.parameters.mesh_size_m=0.0024", "geometry.parameters.tip_mesh_size_m=0.001",
               "output.fields=false", "output.plots=false"]
    two_d = f14(run_case_quiet(FOURIER, tmp_path / "2d", *profile))
    full = ["geometry.parameters.full_outer_electrode=true", 'electrodes.common.facets=["inner", "outer"]']
    diff = {}
    for arc in (0.0006, 0.0003):
        three_d = f14(run_case_quiet(SECTOR, tmp_path / f"3d{arc}", *profile, *full,
                                     f"geometry.parameters.arc_mesh_size_m={arc}"))
        diff[arc] = three_d / two_d - 1
    assert diff[0.0006] > diff[0.0003] > 0, diff
    assert 3.0 < diff[0.0006] / diff[0.0003] < 5.0, diff
    assert diff[0.0003] < 3e-4, diff
