"""Bad input: one clear line naming the file and the key, exit status 2, no traceback."""

import pytest
from conftest import CASES

BAR = CASES / "validation" / "pzt4-bar-axisymmetric.toml"
PZT_E_NOT_PD = ("{c11_Pa=139e9, c12_Pa=77.8e9, c13_Pa=160e9, c33_Pa=115e9, c44_Pa=25.6e9, e31_C_per_m2=-5.6, "
                "e33_C_per_m2=15.1, e15_C_per_m2=12.7, eps11_rel=730, eps33_rel=635}")


def _assert_one_line_error(result, *fragments):
    assert result.returncode == 2, result.stderr + result.stdout
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.mark.parametrize("override, key", [
    ("modal.n_mode=3", "modal.n_mode"),
    ('modal.n_modes="six"', "modal.n_modes"),
    ("modal.target_frequency_Hz=0", "modal.target_frequency_Hz"),
    ("modal.target_frequency_Hz=-5e3", "modal.target_frequency_Hz"),
    ("materials.pzt4.density_kg_per_m3=-7500", "materials.pzt4.density_kg_per_m3"),
    ("materials.steel={young_Pa=-2e11, poisson=0.3, density_kg_per_m3=7850}", "materials.steel.young_Pa"),
    ("materials.steel={young_Pa=2e11, poisson=0.3, density_kg_per_m3=0}", "materials.steel.density_kg_per_m3"),
    (f"materials.pzt4.piezo_e={PZT_E_NOT_PD}", "materials.pzt4.piezo_e"),
    ("materials.pzt4.library=\"PZT-9\"", "materials.pzt4.library"),
    ('geometry.model="cubic"', "geometry.model"),
    ('analyses=["modal", "fatigue"]', "analyses[1]"),
])
def test_invalid_values_name_file_and_key(cli, override, key):
    result = cli("validate", BAR, "--set", override)
    _assert_one_line_error(result, str(BAR.name), key)


def test_missing_electrode_tag(cli):
    result = cli("validate", BAR, "--set", 'electrodes.hot.facets=["electrode_hot"]')
    _assert_one_line_error(result, "electrodes.hot.facets[0]", "not in the mesh")


def test_missing_material_tag(cli, tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(BAR.read_text().replace('cells = "piezo"', 'cells = "ceramic"'))
    _assert_one_line_error(cli("run", case, "--out", tmp_path / "o"), "case.toml", "regions[0].cells")


def test_undefined_material_name(cli, tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(BAR.read_text().replace('material = "pzt4"', 'material = "pzt5"'))
    _assert_one_line_error(cli("validate", case), "regions[0].material")


@pytest.mark.parametrize("content", [None, "this is not a mesh\n", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"])
def test_unreadable_mesh(cli, tmp_path, content):
    mesh = tmp_path / "part.msh"
    if content is not None:
        mesh.write_text(content)
    case = tmp_path / "case.toml"
    text = BAR.read_text().replace('builder = "bar"', 'mesh_file = "part.msh"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("parameters"))
    case.write_text(text)
    _assert_one_line_error(cli("validate", case), "case.toml", "geometry.mesh_file")


def test_unreadable_and_malformed_case_files(cli, tmp_path):
    _assert_one_line_error(cli("validate", tmp_path / "absent.toml"), "absent.toml", "cannot read")
    bad = tmp_path / "bad.toml"
    bad.write_text("[modal\ntarget = 1\n")
    _assert_one_line_error(cli("validate", bad), "bad.toml", "invalid TOML")


def test_valid_case_validates(cli):
    result = cli("validate", BAR)
    assert result.returncode == 0, result.stderr
    assert "valid" in result.stdout
