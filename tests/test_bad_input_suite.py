"""The bad-input suite: every class of bad input (a key's type, range, unknown names, cross-key rules,
mesh-dependent references, files, command-line flags, output paths, checkpoints, MPI) gives exit
status 2 and one line on stderr naming the file and the key, with no traceback, for both
``piezodyn validate`` and ``piezodyn run`` (``validate`` runs every check ``run`` runs).

Most inputs go through ``app.cli.main`` in this process (fast); a handful through ``mpirun -n 2``
subprocesses (no hang, one line from rank 0).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import CASES, run_cli
from mpi4py import MPI

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="in-process CLI calls and own mpirun subprocesses")

BAR = CASES / "validation" / "pzt4-bar-axisymmetric.toml"
FE = CASES / "usdc-fe.toml"
LUMPED = CASES / "usdc-lumped.toml"
TRANSDUCER = CASES / "usdc-transducer.toml"
STRIP = CASES / "validation" / "strip-friction-drive.toml"
MOTOR = CASES / "wwusm-motor.toml"
_CONE = "transient.contacts[0]"
_ROTOR = "transient.bodies[0]"
_SPIN = "transient.bodies[0].rotations[0]"
_WAVE = "transient.base_motions[0]"
# the drill scene on the 4 mm test mesh, 0.2 ms: if a bad input slipped through, the run stays short
FE_TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
           "output.plots=false", "transient.end_time_s=2e-4"]

# (case, --set overrides, the key the line must name)
SET_INPUTS = [
    # types
    (BAR, ['modal.n_modes="six"'], "modal.n_modes"),
    (BAR, ["modal.n_modes=1e20"], "modal.n_modes"),
    (BAR, ["modal.n_modes=true"], "modal.n_modes"),
    (BAR, ["geometry.degree=2.0"], "geometry.degree"),
    (BAR, ['modal.target_frequency_Hz="70 kHz"'], "modal.target_frequency_Hz"),
    (BAR, ['title=5'], "title"),
    (BAR, ['output.fields="yes"'], "output.fields"),
    (BAR, ['output.derived=["von mises"]'], "output.derived[0]"),
    (BAR, ['output.derived="stress"'], "output.derived"),
    (BAR, ['output.derived=["stress", "strain", "stress"]'], "output.derived[2]"),
    (BAR, ['damping.material_quality=1'], "damping.material_quality"),
    (BAR, ['points.end.coordinates_m="0, 0.02"'], "points.end.coordinates_m"),
    (BAR, ['points.end.coordinates_m=[0.0, "top"]'], "points.end.coordinates_m[1]"),
    (BAR, ['modal=3'], "modal"),
    (BAR, ['electrodes.hot.facets="top"'], "electrodes.hot.facets"),
    # ranges and absurd values
    (BAR, ["modal.n_modes=0"], "modal.n_modes"),
    (BAR, ["modal.n_modes=100000000000000000000"], "modal.n_modes"),
    (BAR, ["modal.n_modes=5000"], "modal.n_modes"),
    (BAR, ["modal.target_frequency_Hz=0"], "modal.target_frequency_Hz"),
    (BAR, ["modal.target_frequency_Hz=-5e3"], "modal.target_frequency_Hz"),
    (BAR, ["modal.target_frequency_Hz=nan"], "modal.target_frequency_Hz"),
    (BAR, ["modal.target_frequency_Hz=inf"], "modal.target_frequency_Hz"),
    (BAR, ["geometry.degree=4"], "geometry.degree"),
    (BAR, ["harmonic.n_points=1"], "harmonic.n_points"),
    (BAR, ["harmonic.voltage_V=0"], "harmonic.voltage_V"),
    (BAR, ["damping.alpha_per_s=-1"], "damping.alpha_per_s"),
    (BAR, ["geometry.parameters.length_m=-0.02"], "geometry.parameters.length_m"),
    (BAR, ["geometry.parameters.axial_divisions=0"], "geometry.parameters.axial_divisions"),
    (BAR, ["materials.pzt4.density_kg_per_m3=-7500"], "materials.pzt4.density_kg_per_m3"),
    (BAR, ["materials.steel={young_Pa=-2e11, poisson=0.3, density_kg_per_m3=7850}"], "materials.steel.young_Pa"),
    (BAR, ["materials.steel={young_Pa=2e11, poisson=0.3, density_kg_per_m3=0}"], "materials.steel.density_kg_per_m3"),
    # unknown names
    (BAR, ["modal.n_mode=3"], "modal.n_mode"),
    (BAR, ["modall.n_modes=3"], "modall"),
    (BAR, ["geometry.parameters.colour=1"], "geometry.parameters.colour"),
    (BAR, ['modal.electrical="closed"'], "modal.electrical"),
    (BAR, ['modal.working_mode="first"'], "modal.working_mode"),
    (BAR, ['geometry.model="cubic"'], "geometry.model"),
    (BAR, ['geometry.builder="cube"'], "geometry.builder"),
    (BAR, ['analyses=["modal", "fatigue"]'], "analyses[1]"),
    (BAR, ['materials.pzt4.library="PZT-9"'], "materials.pzt4.library"),
    (BAR, ['electrodes.hot.kind="live"'], "electrodes.hot.kind"),
    (BAR, ['points.end.component="w"'], "points.end.component"),
    (BAR, ['circuit.point="nowhere"'], "circuit.point"),
    (BAR, ['harmonic.target={point="nowhere", amplitude_m=1e-6}'], "harmonic.target.point"),
    (BAR, ['source="elsewhere.toml"'], "source"),
    # cross-key rules
    (BAR, ['tier="lumped"'], "lumped"),
    (BAR, ['analyses=["lumped"]'], "analyses[0]"),
    (BAR, ['analyses=["circuit"]'], "analyses"),
    (BAR, ['analyses=["harmonic"]'], "harmonic.f_start_Hz"),
    (BAR, ['analyses=["modal", "modal"]'], "analyses"),
    (BAR, ['analyses=[]'], "analyses"),
    (BAR, ['analyses=["transient"]'], "transient"),
    (BAR, ["harmonic.f_start_Hz=60e3"], "harmonic.f_stop_Hz"),
    (BAR, ["harmonic.f_start_Hz=80e3", "harmonic.f_stop_Hz=60e3"], "harmonic.f_stop_Hz"),
    (BAR, ['geometry.mesh_file="bar.msh"'], "geometry.builder"),
    (BAR, ["electrodes.ground.amplitude_V=3"], "electrodes.ground.amplitude_V"),
    (BAR, ['electrodes.hot.kind="ground"'], "electrodes"),
    (BAR, ['electrodes.hot.kind="ground"', 'analyses=["modal", "harmonic"]',
           'harmonic.target={point="end", amplitude_m=1e-6}'], "electrodes"),
    (LUMPED, ['analyses=["modal"]'], "analyses[0]"),
    (LUMPED, ["lumped.duration_s=-1"], "lumped.duration_s"),
    (LUMPED, ['lumped.source="circuit"'], "lumped.circuit_file"),
    # mesh-dependent (validate must find them too)
    (BAR, ['electrodes.hot.facets=["electrode_hot"]'], "electrodes.hot.facets[0]"),
    (BAR, ['regions=[{cells="ceramic", material="pzt4"}]'], "regions[0].cells"),
    (BAR, ["points.end.coordinates_m=[0.5, 0.5]"], "points.end"),
    (FE, [*FE_TINY, 'transient.drive.point="nowhere"'], "transient.drive.point"),
    (FE, [*FE_TINY, "transient.loads.gravity_m_per_s2=[0.0, 0.0, -9.81]"], "transient.loads.gravity_m_per_s2"),
    (FE, [*FE_TINY, "transient.loads.fe_force_N=[0.0]"], "transient.loads.fe_force_N"),
    (FE, [*FE_TINY, 'electrodes.hot.kind="ground"'], "transient.drive.tip_amplitude_m"),
    (FE, [*FE_TINY, "transient.end_time_s=-2e-4"], "transient.end_time_s"),
    # a drive locked to the resonance (app/case/transient.py DriveSection, app/case/schema.py Case.check)
    (FE, [*FE_TINY, "transient.drive.detuning_Hz=10.0"], "transient.drive.detuning_Hz"),
    (FE, [*FE_TINY, "transient.drive.lock_modes=1"], "transient.drive.lock_modes"),
    (FE, [*FE_TINY, 'transient.drive.lock="phase"'], "transient.drive.lock"),
    (FE, [*FE_TINY, 'transient.drive.lock="resonance"', "transient.drive.detuning_Hz=-20000.0"],
     "transient.drive.detuning_Hz"),
    (FE, [*FE_TINY, 'transient.drive.lock="resonance"', "transient.drive.lock_modes=0"],
     "transient.drive.lock_modes"),
    (MOTOR, [f"electrodes.{e}.amplitude_V=0.0" for e in ("A", "B", "Am", "Bm")], "transient.drive.lock"),
    # the phase-locked field frames (app/case/schema.py OutputSection.check_frames)
    (FE, [*FE_TINY, "output.field_phases=0"], "output.field_phases"),
    (FE, [*FE_TINY, "output.field_phases=100"], "output.field_phases"),
    (FE, [*FE_TINY, "output.field_interval_periods=0.5"], "output.field_interval_periods"),
    (FE, [*FE_TINY, "output.field_interval_periods=2", "output.field_burst_times_s=[0.0]"],
     "output.field_burst_times_s"),
    (FE, [*FE_TINY, "output.field_burst_times_s=[0.0, 1e-5]"], "output.field_burst_times_s[1]"),
    (FE, [*FE_TINY, "output.field_burst_times_s=[0.0, 5e-4]"], "output.field_burst_times_s[1]"),
    (FE, [*FE_TINY, "output.field_burst_times_s=[-1e-4]"], "output.field_burst_times_s[0]"),
    (BAR, ["output.field_phases=4"], "output.field_phases"),
    (FE, [*FE_TINY, "transient.output_interval_s=1.0"], "transient.end_time_s: 0.0002 s is shorter than "
                                                        "output_interval_s = 1 s"),
    (FE, [*FE_TINY, 'transient.initial_state="warm"'], "transient.initial_state"),
    (FE, [*FE_TINY, "transient.steps.min_s=1e-6"], "transient.steps.min_s"),
    (FE, [*FE_TINY, "transient.scheme.rho_inf=2"], "transient.scheme.rho_inf"),
    (FE, [*FE_TINY, "transient.checkpoint_interval_steps=-1"], "transient.checkpoint_interval_steps"),
    # the contact pressure: the FE and modal tiers' transient, of a surface contact (docs/contact.md)
    (FE, [*FE_TINY, "output.contact_pressure=true"], "output.contact_pressure"),        # no surface contact
    (TRANSDUCER, ["output.contact_pressure=true"], "output.contact_pressure"),          # no transient analysis
    # the lumped bodies file: frames no closer than the samples, within the run
    (LUMPED, ["lumped.output.bodies_interval_s=1e-6"], "lumped.output.bodies_interval_s"),
    (LUMPED, ["lumped.output.bodies_interval_s=1.0"], "lumped.output.bodies_interval_s"),
    (LUMPED, ["lumped.output.bodies_interval_s=-1e-3"], "lumped.output.bodies_interval_s"),
    # prescribed travelling wave
    (STRIP, [f'{_WAVE}.facets="nowhere"'], f"{_WAVE}.facets"),
    (STRIP, [f"{_WAVE}.direction=[0.0, 0.0]"], f"{_WAVE}.direction"),
    (STRIP, [f"{_WAVE}.normal=[1.0, 0.0]"], f"{_WAVE}.normal"),
    (STRIP, [f"{_WAVE}.normal=[0.0, 1.0, 0.0]"], f"{_WAVE}.normal"),
    (STRIP, [f"{_WAVE}.ramp_periods=0"], f"{_WAVE}.ramp_periods"),
    (STRIP, [f'{_WAVE}.kind="standing_wave"'], f"{_WAVE}.kind"),
    (STRIP, [f"{_WAVE}.wavelength_m=-0.02"], f"{_WAVE}.wavelength_m"),
    (STRIP, [f"{_WAVE}.mass_kg=1"], f"{_WAVE}.mass_kg"),
    (STRIP, ['transient.initial_state="harmonic"'], "transient.initial_state"),
    (STRIP, ['supports=[{facets=["bottom"], components=["x"]}]'], f"{_WAVE}.facets"),
    # the motor: cone contact, rotor, steady state (refused when the case is read, before any mesh)
    (MOTOR, [f"{_CONE}.axis=[0.0, 1.0, 0.0]"], f"{_CONE}.axis"),
    (MOTOR, [f"{_CONE}.half_angle_deg=95"], f"{_CONE}.half_angle_deg"),
    (MOTOR, [f'{_CONE}.shape="plane"'], f"{_CONE}.normal"),
    (MOTOR, [f'{_ROTOR}.rotations[0].axis="x"'], f"{_ROTOR}.rotations"),
    (MOTOR, [f"{_ROTOR}.rotations[0].brake_N_m_s_per_rad=-1"], f"{_ROTOR}.rotations[0].brake_N_m_s_per_rad"),
    (MOTOR, [f'{_ROTOR}.rotations[0].motion="fixed"', f"{_ROTOR}.rotations[0].brake_N_m_s_per_rad=0.1"],
     f"{_ROTOR}.rotations[0].brake_N_m_s_per_rad"),
    (MOTOR, ["reduction.interface_nodes=100000"], "reduction.interface_nodes"),      # more than the band has
    # the band interface: ring sampling with interpolated sites only
    (MOTOR, ['reduction.interface="band"', 'reduction.site_displacement="field"'], "reduction.interface"),
    (FE, ['tier="modal"', 'reduction.interface="band"'], "reduction.interface"),
    (MOTOR, ['reduction.interface="ring"'], "reduction.interface"),
    # rings across the band: a cone's ring sampling, and a modal interface that sees the band's tilt
    (MOTOR, [f"{_CONE}.sample_rings=3"], f"{_CONE}.sample_rings"),
    (MOTOR, [f'{_CONE}.sampling="nodes"', f"{_CONE}.sample_rings=2"], f"{_CONE}.sample_rings"),
    (MOTOR, [f"{_CONE}.sample_rings=0"], f"{_CONE}.sample_rings"),
    (MOTOR, ["reduction.ring_points=64"], "reduction.ring_points"),                   # a key of the old motor path
    # cone obstacle, brake, steady-state stop (the motor case: caught before its mesh is built)
    (MOTOR, [f"{_CONE}.axis=[0.0, 0.0, 2.0]"], f"{_CONE}.axis"),
    (MOTOR, [f"{_CONE}.axis=[0.0, 1.0]"], f"{_CONE}.axis"),
    (MOTOR, [f"{_CONE}.half_angle_deg=90.0"], f"{_CONE}.half_angle_deg"),
    (MOTOR, [f"{_CONE}.half_angle_deg=0.0"], f"{_CONE}.half_angle_deg"),
    (MOTOR, [f"{_CONE}.radius_m=-0.0128"], f"{_CONE}.radius_m"),
    (MOTOR, [f'{_CONE}.axis="z"'], f"{_CONE}.axis"),
    (STRIP, ['transient.contacts[0].shape="cone"'], "transient.contacts[0].radius_m"),
    (MOTOR, [f"{_SPIN}.brake_N_m_s_per_rad=-1e-6"], f"{_SPIN}.brake_N_m_s_per_rad"),
    (MOTOR, [f'{_SPIN}.motion="constant_rate"', f"{_SPIN}.brake_N_m_s_per_rad=1e-6"],
     f"{_SPIN}.brake_N_m_s_per_rad"),
    (MOTOR, ['transient.steady_state.body="stator"'], "transient.steady_state.body"),
    (MOTOR, ["transient.steady_state.window_cycles=1"], "transient.steady_state.window_cycles"),
    (MOTOR, ["transient.steady_state.relative_tolerance=0"], "transient.steady_state.relative_tolerance"),
    (MOTOR, ["transient.steady_state.relative_tolerance=1.5"], "transient.steady_state.relative_tolerance"),
    (MOTOR, ["transient.steady_state.min_cycles=0"], "transient.steady_state.min_cycles"),
    (MOTOR, ["transient.steady_state.period_count=3"], "transient.steady_state.period_count"),
    (MOTOR, ["transient.bodies[0].rotations=[]"], "transient.steady_state.body"),
    (MOTOR, ['transient.steady_state.rule="fit"'], "transient.steady_state.rule"),
    (MOTOR, ['tier="fe"', 'transient.steady_state.rule="orbit"'], "transient.steady_state.rule"),
    # warm starts (transient.start_from): the modal tier's, from a result directory with a checkpoint
    (MOTOR, ['tier="fe"', 'transient.start_from="elsewhere"'], "transient.start_from"),
    (MOTOR, ['transient.start_from=""'], "transient.start_from"),
    (MOTOR, ['transient.start_from="no-such-run-directory"'], "transient.start_from"),
    (STRIP, ['tier="modal"', 'transient.start_from="elsewhere"'], "transient.start_from"),
    # excluded initial gap and seating (docs/contact.md)
    (MOTOR, [f"{_CONE}.exclude_initial_gap=1"], f"{_CONE}.exclude_initial_gap"),
    (MOTOR, [f'{_ROTOR}.seat_on="nowhere"'], f"{_ROTOR}.seat_on"),
    (MOTOR, ['tier="fe"', f'{_ROTOR}.seat_on="nowhere"'], f"{_ROTOR}.seat_on"),
    (MOTOR, ['tier="fe"', f"{_ROTOR}.free_axes=[false, true, true]"], f"{_ROTOR}.seat_on"),
    (MOTOR, ['tier="fe"', f"{_ROTOR}.fixed=true", f'{_SPIN}.motion="fixed"'], f"{_ROTOR}.seat_on"),
    # ... and those that need the mesh (the 2D strip: cheap)
    (STRIP, ['transient.contacts[0].shape="cone"', "transient.contacts[0].radius_m=0.01",
             "transient.contacts[0].axis=[0.0, 0.0, 1.0]", "transient.contacts[0].half_angle_deg=15.0"],
     "transient.contacts[0].shape"),
    (STRIP, ["transient.contacts=[]", 'transient.bodies[0].rotations=[{axis="plane", motion="constant_rate"}]',
             'transient.steady_state={body="slider"}'], "transient.steady_state.body"),
]
# --set syntax: the line names --set and the key
SYNTAX_INPUTS = [(BAR, ["modal.n_modes"], "modal.n_modes"), (BAR, ["modal..n_modes=3"], "modal..n_modes=3"),
                 (BAR, ["title.sub=3"], "title"), (BAR, ["=3"], "=3"),
                 (STRIP, ["transient.bodies[3].mass_kg=1"], "transient.bodies[3]"),
                 (STRIP, ["transient.drive[0].frequency_Hz=1"], "transient.drive[0]")]

# (case, [(old text, new text)], --set overrides, key): edits of the case file itself
_CONTACTS = "[[transient.contacts]]\nname = \"tip_ball\""
EDIT_INPUTS = [
    (BAR, [('material = "pzt4"', 'material = "pzt5"')], [], "regions[0].material"),
    (BAR, [('poling = "+z"', 'poling = "+w"')], [], "regions[0].poling"),
    (BAR, [('poling = "+z"', "poling = [0.0, 0.0, 0.0]")], [], "regions[0].poling"),
    (BAR, [('kind = "ground"', 'kind = "ground"\nphase_deg = 30.0')], [], "electrodes.ground.phase_deg"),
    (FE, [("direction = [0.0, 1.0]", "direction = [0.0, 0.0]")], FE_TINY, "transient.contacts[1].direction"),
    (FE, [("direction = [0.0, 1.0]", "direction = [0.0, 1.0, 0.0]")], FE_TINY, "transient.contacts[1].direction"),
    (FE, [("normal = [0.0, 1.0]", "normal = [0.0, 0.0]")], FE_TINY, "transient.contacts[0].normal"),
    (FE, [('node_point = "tip"', 'node_point = "nowhere"')], FE_TINY, "transient.contacts[0].node_point"),
    (FE, [(_CONTACTS, '[[transient.contacts]]\nname = "tip_ball_face"\nkind = "surface"\nfacets = "nowhere"\n'
           'body = "ball"\nnormal = [0.0, 1.0]\nstiffness = 1e12\n' + _CONTACTS)], FE_TINY,
     "transient.contacts[0].facets"),
    (FE, [('lower = "stem"', 'lower = "shaft"')], FE_TINY, "transient.contacts[1].lower"),
    (FE, [("position_m = [0.0, -0.00401]", "position_m = [0.0, -0.00401, 0.0]")], FE_TINY, "transient.bodies"),
    (FE, [('name = "stem"  ', 'name = "ball"  ')], FE_TINY, "transient.bodies[1].name"),
    (FE, [("mass_kg = 0.040", "mass_kg = 0.0")], FE_TINY, "transient.bodies[1].mass_kg"),
    (FE, [('kind = "node"', 'kind = "edge"')], FE_TINY, "transient.contacts[0].kind"),
    (FE, [('[transient.drive]', '[transient.drive]\ncolour = "red"')], FE_TINY, "transient.drive.colour"),
]


def cli_main(capsys, *args) -> tuple[int, str]:
    """``piezodyn ARGS`` in this process: (exit status, stderr)."""
    from app.cli import main

    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def assert_one_line(code: int, err: str, *fragments) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    for fragment in fragments:
        assert str(fragment) in lines[0], lines[0]


def _sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def _command(command, case, overrides, tmp_path):
    out = ["--out", tmp_path / "out"] if command == "run" else []
    return [command, case, *_sets(overrides), *out, *(["--quiet"] if command == "run" else [])]


def _ids(entries):
    return [f"{Path(e[0]).stem}:{e[-1]}:{i}" for i, e in enumerate(entries)]


def refused_alike(capsys, case, overrides, tmp_path, *fragments) -> str:
    """``validate`` then ``run`` of one input: both exit 2 with one line holding ``fragments``, and the two
    lines are the same (``validate`` runs every check ``run`` runs, on one check path). Returns the line.
    (``validate`` first: an input it misses fails the test before ``run`` starts a long simulation.)"""
    lines = []
    for command in ("validate", "run"):
        code, err = cli_main(capsys, *_command(command, case, overrides, tmp_path))
        assert_one_line(code, err, *fragments)
        lines.append(err)
    assert lines[1] == lines[0], f"validate: {lines[0]}run: {lines[1]}"
    return lines[0]


@pytest.mark.parametrize("case, overrides, key", SET_INPUTS, ids=_ids(SET_INPUTS))
def test_bad_value_is_one_line_naming_file_and_key(capsys, tmp_path, case, overrides, key):
    refused_alike(capsys, case, overrides, tmp_path, case.name, key)
    assert not (tmp_path / "out" / "summary.json").exists()


@pytest.mark.parametrize("case, overrides, key", SYNTAX_INPUTS, ids=_ids(SYNTAX_INPUTS))
def test_bad_set_syntax_is_one_line(capsys, tmp_path, case, overrides, key):
    refused_alike(capsys, case, overrides, tmp_path, "--set", key)


def edited_case(case: Path, edits, directory: Path) -> Path:
    """``case`` with each (old, new) text replaced once, written into ``directory``."""
    text = case.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    edited = directory / f"edited-{case.name}"
    edited.write_text(text)
    return edited


@pytest.mark.parametrize("case, edits, overrides, key", EDIT_INPUTS, ids=_ids(EDIT_INPUTS))
def test_bad_case_file_is_one_line_naming_file_and_key(capsys, tmp_path, case, edits, overrides, key):
    edited = edited_case(case, edits, tmp_path)
    refused_alike(capsys, edited, overrides, tmp_path, edited.name, key)


# ------------------------------------------------------------------------------------ files
def _mesh_case(tmp_path: Path, mesh_bytes: bytes | None) -> Path:
    if mesh_bytes is not None:
        (tmp_path / "part.msh").write_bytes(mesh_bytes)
    text = BAR.read_text().replace('builder = "bar"', 'mesh_file = "part.msh"')
    case = tmp_path / "meshcase.toml"
    case.write_text("\n".join(line for line in text.splitlines() if not line.startswith("parameters")))
    return case


FILE_INPUTS = {
    "absent case": (lambda d: d / "absent.toml", "absent.toml", "cannot read"),
    "case is a directory": (lambda d: d, "", "cannot read"),
    "malformed TOML": (lambda d: _write(d / "bad.toml", b"[modal\ntarget = 1\n"), "bad.toml", "invalid TOML"),
    "case not UTF-8": (lambda d: _write(d / "latin.toml", 'title = "Pi\xe9zo"\n'.encode("latin-1")
                                        + BAR.read_bytes()[BAR.read_bytes().index(b"tier"):]),
                       "latin.toml", "not UTF-8"),
    "mesh file absent": (lambda d: _mesh_case(d, None), "meshcase.toml", "geometry.mesh_file"),
    "mesh file not a mesh": (lambda d: _mesh_case(d, b"this is not a mesh\n"), "meshcase.toml", "geometry.mesh_file"),
    "mesh file binary garbage": (lambda d: _mesh_case(d, bytes(range(256)) * 4), "meshcase.toml", "geometry.mesh_file"),
    "circuit file absent": (lambda d: _lumped_circuit(d, None), "lumpedcase.toml", "lumped.circuit_file"),
    "circuit file not UTF-8": (lambda d: _lumped_circuit(d, b"\xff\xfe{\x00}"), "lumpedcase.toml",
                               "lumped.circuit_file"),
    "circuit file truncated JSON": (lambda d: _lumped_circuit(d, b'{"modal_mass_kg": 0.05, "modal_sti'),
                                    "lumpedcase.toml", "lumped.circuit_file"),
}


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _lumped_circuit(tmp_path: Path, circuit: bytes | None) -> Path:
    if circuit is not None:
        (tmp_path / "circuit.json").write_bytes(circuit)
    text = LUMPED.read_text().replace('source = "typed"', 'source = "circuit"\ncircuit_file = "circuit.json"')
    return _write(tmp_path / "lumpedcase.toml", text.encode())


@pytest.mark.parametrize("name", list(FILE_INPUTS))
def test_bad_file_is_one_line(capsys, tmp_path, name):
    make, file, fragment = FILE_INPUTS[name]
    refused_alike(capsys, make(tmp_path), [], tmp_path, file, fragment)


# ------------------------------------------------------------------------------ command line
def test_command_line_errors_are_one_line(capsys, tmp_path):
    assert_one_line(*cli_main(capsys, "run"), "command line", "case")
    assert_one_line(*cli_main(capsys, "run", BAR, "--frobnicate"), "command line", "--frobnicate")
    assert_one_line(*cli_main(capsys, "explode", BAR), "command line", "explode")
    assert_one_line(*cli_main(capsys, "run", BAR, "--out", tmp_path / "a", "--resume", tmp_path / "b"), "--out")


@pytest.fixture
def a_file(tmp_path) -> Path:
    path = tmp_path / "a-file.txt"
    path.write_text("not a directory\n")
    return path


@pytest.mark.parametrize("where", ["existing file", "under a file", "not creatable"])
def test_bad_out_is_one_line(capsys, a_file, where):
    out = {"existing file": a_file, "under a file": a_file / "sub", "not creatable": Path("/dev/null/x")}[where]
    assert_one_line(*cli_main(capsys, "run", BAR, "--out", out, "--quiet"), "--out", str(out))
    assert a_file.read_text() == "not a directory\n"


def test_sweep_bad_out_is_one_line(capsys, a_file):
    from app import sweep

    code = sweep.main([str(LUMPED), "--param", "lumped.downforce_N=0,3", "--out", str(a_file), "--no-progress"])
    assert_one_line(code, capsys.readouterr().err, "--out", str(a_file))


@pytest.fixture(scope="module")
def finished_fe_run(tmp_path_factory) -> Path:
    """A tiny drill run to 0.2 ms with its checkpoint (resumed below with bad arguments)."""
    out = tmp_path_factory.mktemp("finished")
    result = run_cli("run", FE, "--out", out, "--quiet", *_sets(FE_TINY))
    assert result.returncode == 0, result.stderr[-2000:]
    return out


def _copy(run_dir: Path, tmp_path: Path) -> Path:
    target = tmp_path / "resumed"
    shutil.copytree(run_dir, target)
    return target


def test_resume_errors_are_one_line(capsys, tmp_path, a_file, finished_fe_run):
    sets = _sets(FE_TINY)
    # a file, a missing directory, a directory without a checkpoint
    assert_one_line(*cli_main(capsys, "run", FE, "--resume", a_file, *sets), "--resume", "existing file")
    assert_one_line(*cli_main(capsys, "run", FE, "--resume", tmp_path / "nothing", *sets), "--resume")
    (tmp_path / "empty").mkdir()
    assert_one_line(*cli_main(capsys, "run", FE, "--resume", tmp_path / "empty", *sets), "--resume", "no checkpoint")
    # a case without a transient analysis
    assert_one_line(*cli_main(capsys, "run", BAR, "--resume", finished_fe_run), BAR.name, "--resume")
    # a lumped case (resumable) on an FE run's checkpoint: another case, named by its first differing key
    assert_one_line(*cli_main(capsys, "run", LUMPED, "--resume", finished_fe_run), LUMPED.name,
                    "differs from the checkpointed run")
    # an end time before the checkpoint's time: nothing rewritten
    before = (finished_fe_run / "summary.json").read_bytes()
    assert_one_line(*cli_main(capsys, "run", FE, "--resume", finished_fe_run, *sets, "--set",
                              "transient.end_time_s=1e-4"), FE.name, "transient.end_time_s")
    assert (finished_fe_run / "summary.json").read_bytes() == before
    # a different case
    assert_one_line(*cli_main(capsys, "run", FE, "--resume", finished_fe_run, *sets, "--set",
                              "transient.drive.frequency_Hz=20000.0"), FE.name, "transient.drive.frequency_Hz")


@pytest.mark.parametrize("damage", ["truncated", "not UTF-8", "not an object", "state file missing", "no seq"])
def test_damaged_checkpoint_is_one_line(capsys, tmp_path, finished_fe_run, damage):
    out = _copy(finished_fe_run, tmp_path)
    pointer = out / "checkpoint" / "checkpoint.json"
    text = pointer.read_bytes()
    meta = json.loads(text)
    if damage == "truncated":
        pointer.write_bytes(text[: len(text) // 2])
    elif damage == "not UTF-8":
        pointer.write_bytes(b"\xff" + text)
    elif damage == "not an object":
        pointer.write_text("[1, 2, 3]")
    elif damage == "state file missing":
        (out / "checkpoint" / f"state-{meta['seq']}.npz").unlink()
    else:
        del meta["seq"]
        pointer.write_text(json.dumps(meta))
    code, err = cli_main(capsys, "run", FE, "--resume", out, *_sets(FE_TINY))
    assert_one_line(code, err, "checkpoint.json")


# ------------------------------------------------------------------------------------ MPI
MPI_INPUTS = {
    "out is a file": lambda d, f: (["run", BAR, "--out", f], ["--out"]),
    "out under a file": lambda d, f: (["run", BAR, "--out", f / "x"], ["--out"]),
    "unknown key": lambda d, f: (["validate", BAR, "--set", "modal.n_mode=3"], [BAR.name, "modal.n_mode"]),
    "unknown drive point (mesh)": lambda d, f: (["validate", FE, *_sets([*FE_TINY, 'transient.drive.point="x"'])],
                                                [FE.name, "transient.drive.point"]),
    "base motion on a missing facet group (mesh)": lambda d, f: (
        ["run", STRIP, "--out", d / "strip", "--set", 'transient.base_motions[0].facets="nowhere"'],
        [STRIP.name, "transient.base_motions[0].facets"]),
    "contact pressure without a surface contact": lambda d, f: (
        ["validate", FE, *_sets([*FE_TINY, "output.contact_pressure=true"])], [FE.name, "output.contact_pressure"]),
    "resume a file": lambda d, f: (["run", FE, "--resume", f, *_sets(FE_TINY)], ["--resume"]),
    "sweep out is a file": lambda d, f: (["sweep", LUMPED, "--param", "lumped.downforce_N=0,3", "--out", f],
                                         ["--out"]),
}


def run_two_ranks(*args):
    """``mpirun --quiet -n 2 python -m app ARGS`` (--quiet: without it mpirun adds its own notice
    that a rank exited with a non-zero status). The timeout turns a hang into a failure."""
    import os
    import subprocess
    import sys

    from conftest import ROOT

    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", PYTHONPATH=str(ROOT))
    cmd = ["mpirun", "--quiet", "-n", "2", sys.executable, "-m", "app", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180, cwd=ROOT, env=env)


@pytest.mark.parametrize("name", list(MPI_INPUTS))
def test_bad_input_on_two_ranks_is_one_line_and_no_hang(tmp_path, a_file, name):
    args, fragments = MPI_INPUTS[name](tmp_path, a_file)
    result = run_two_ranks(*args)
    assert_one_line(result.returncode, result.stderr, *fragments)


def test_truncated_checkpoint_on_two_ranks(tmp_path, finished_fe_run):
    out = _copy(finished_fe_run, tmp_path)
    pointer = out / "checkpoint" / "checkpoint.json"
    pointer.write_bytes(pointer.read_bytes()[:40])
    result = run_two_ranks("run", FE, "--resume", out, *_sets(FE_TINY))
    assert_one_line(result.returncode, result.stderr, "checkpoint.json")


# ------------------------------------------------------------------- valid inputs stay valid
@pytest.mark.parametrize("case, overrides", [
    (BAR, ["geometry.parameters.width_m=0.0003"]),                         # a thin bar: end faces found
    (BAR, ["geometry.parameters.width_m=0.0003", "geometry.parameters.lateral_divisions=1"]),
    (BAR, ["geometry.parameters.width_m=0.05", "geometry.parameters.length_m=0.001",
           "points.end.coordinates_m=[0.0, 0.001]"]),                         # a flat disc-like bar
    (FE, FE_TINY),
    (TRANSDUCER, []),
])
def test_valid_inputs_validate(capsys, case, overrides):
    code, err = cli_main(capsys, "validate", case, *_sets(overrides))
    assert code == 0, err


# What only the old modal motor path refused: the modal tier runs any scene's interactions now (friction,
# contact damping, excluded initial gaps, gravity, base motions without contacts, a body off the axis, any
# scheme), so these inputs are valid in both tiers, as they always were in the FE tier.
ACCEPTED_INPUTS = [
    (STRIP, ['tier="modal"']),
    (STRIP, ['tier="modal"', "transient.contacts=[]"]),
    (STRIP, ['tier="modal"', "transient.contacts[0].exclude_initial_gap=true", "transient.contacts[0].damping=1e3"]),
    (STRIP, ['tier="modal"', 'transient.scheme.kind="generalized_alpha"']),
]


@pytest.mark.parametrize("case, overrides", ACCEPTED_INPUTS, ids=[f"{i}" for i in range(len(ACCEPTED_INPUTS))])
def test_inputs_the_old_motor_path_refused_are_valid(capsys, case, overrides, tmp_path):
    code, err = cli_main(capsys, *_command("validate", case, overrides, tmp_path))
    assert code == 0, err
