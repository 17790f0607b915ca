"""A .msh file read through gmsh gives the same model as the builder; meshio export round-trips."""

import gmsh
import pytest
from conftest import CASES, run_case_quiet
from mpi4py import MPI

from geometry.meshdata import GmshSession
from geometry.specimens import _structured_rectangle


def _write_bar_msh(path):
    with GmshSession(MPI.COMM_SELF, "bar"):
        _structured_rectangle(0.001, 0.02, 2, 20, axisymmetric=True)
        gmsh.write(str(path))


def test_msh_file_matches_builder(tmp_path):
    _write_bar_msh(tmp_path / "bar.msh")
    text = (CASES / "validation/pzt4-bar-axisymmetric.toml").read_text()
    text = text.replace('builder = "bar"', 'mesh_file = "bar.msh"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("parameters"))
    (tmp_path / "case.toml").write_text(text)
    from_file = run_case_quiet(tmp_path / "case.toml", tmp_path / "a", 'analyses=["modal"]', "output.fields=false")
    built = run_case_quiet("validation/pzt4-bar-axisymmetric.toml", tmp_path / "b", 'analyses=["modal"]',
                           "output.fields=false")
    assert from_file["results"]["modal"]["working_resonance_Hz"] == pytest.approx(
        built["results"]["modal"]["working_resonance_Hz"], rel=1e-10)


def test_meshio_export(tmp_path):
    import meshio

    from geometry.builders import BUILDERS
    from geometry.mshfile import export_meshio

    params_cls, build = BUILDERS["transducer"]
    data = build(MPI.COMM_SELF, params_cls(mesh_size_m=0.004, ceramic_mesh_size_m=0.003), "axisymmetric")
    export_meshio(data, tmp_path / "t.vtu")
    back = meshio.read(tmp_path / "t.vtu")
    n_cells = data.mesh.topology.index_map(2).size_local
    assert sum(len(block.data) for block in back.cells) == n_cells
    assert set(back.cell_data["region"][0]) == set(data.cell_names.values())
