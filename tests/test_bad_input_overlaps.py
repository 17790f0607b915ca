"""Issue 29's bad inputs on the new surface (motor, stator, strip, tiers): every list of names, facets or
electrodes refuses duplicates and overlaps; two electrodes that are not both ground may not share a potential
DOF (an electrode is an equipotential surface); ``validate`` makes the mesh checks ``run`` makes (the wave
circle, the identification points); and the line names the key at fault (a stator strip's geometry key, the
end time, a section the tier does not read).

Each input: ``run`` and ``validate`` both exit 2 with one line naming the file and the key, and the two lines
are the same. Marked ``mpi``: on 2 ranks (CI) every rank runs the CLI in this process, collectively (a check
that one rank makes alone would hang); rank 0 prints the line, the other ranks nothing.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import CASES
from mpi4py import MPI
from test_bad_input_suite import cli_main

STATOR = CASES / "wwusm-stator.toml"
MOTOR = CASES / "wwusm-motor.toml"
BAR = CASES / "validation" / "pzt4-bar-axisymmetric.toml"
BAR3D = CASES / "validation" / "pzt4-bar-3d.toml"
STRIP = CASES / "validation" / "strip-friction-drive.toml"
FE = CASES / "usdc-fe.toml"
LUMPED = CASES / "usdc-lumped.toml"
QUIET = ["output.fields=false", "output.plots=false"]
# the 3D bar's frequency-domain analyses, cheap: a circle far outside the 2 mm x 2 mm x 20 mm bar
_WAVE = ('harmonic={f_start_Hz=60e3, f_stop_Hz=80e3, n_points=2, refine_extrema=false, wave={circle_radius_m=0.5, '
         'circle_height_m=0.01, normal_rz=[1.0, 0.0], order=2}}')


def _motions(*named_facets) -> str:
    """--set of transient.base_motions: the strip's wave on each (name, facet group)."""
    wave = ('kind="travelling_wave", normal_amplitude_m=1e-6, tangential_amplitude_m=0.0, wavelength_m=0.02, '
            'direction=[1.0, 0.0], normal=[0.0, 1.0]')
    tables = ", ".join(f'{{name="{n}", facets="{f}", {wave}}}' for n, f in named_facets)
    return f"transient.base_motions=[{tables}]"


_SLIDER = '[[transient.contacts]]\nname = "strip_slider"'
_SLIDER_COPY = ('[[transient.contacts]]\nname = "strip_slider_again"\nkind = "surface"\nfacets = "top"\n'
                'body = "slider"\nshape = "plane"\nnormal = [0.0, -1.0]\nstiffness = 1e13\n'
                '[transient.contacts.friction]\nmu_dynamic = 0.57\n\n')

# name: (case, [(old, new) edits of the case file], --set overrides, fragments the line must hold)
INPUTS = {
    # two electrodes on one facet group, by name (before any mesh)
    "stator: voltage electrodes on one facet group": (
        STATOR, [], ['electrodes.B.facets=["A1","B2","B3","B4"]'], ["electrodes.B.facets[0]", "electrode 'A'"]),
    "motor: voltage electrodes on one facet group": (
        MOTOR, [], ['electrodes.B.facets=["A1","B2","B3","B4"]'], ["electrodes.B.facets[0]", "electrode 'A'"]),
    "motor: ground and voltage electrodes on one facet group": (
        MOTOR, [], ['electrodes.common.facets=["inner","guard","sensor","sensor2","A1"]'],
        ["electrodes.A.facets[0]", "electrode 'common'"]),
    # ... by name and by tag (the mesh), and meeting at an edge (shared potential DOFs)
    "bar: one facet group by name and by tag": (BAR, [], ['electrodes.hot.facets=["top", 2]'],
                                                ["electrodes.hot.facets[1]", "'top'"]),
    "bar: voltage electrodes meeting at an edge": (
        BAR, [], ['electrodes.ground.kind="voltage"',
                  'electrodes.side={facets=["side"], kind="voltage", phase_deg=90.0}'],
        ["electrodes.side.facets", "shares potential DOFs with electrode 'ground'"]),
    "bar: floating electrodes meeting at an edge": (
        BAR, [], ['electrodes.ground.kind="floating"', 'electrodes.side={facets=["side"], kind="floating"}'],
        ["electrodes.side.facets", "shares potential DOFs with electrode 'ground'"]),
    # a name listed twice in one list
    "stator: a facet twice in an electrode": (
        STATOR, [], ['electrodes.B.facets=["B1","B2","B3","B3"]'], ["electrodes.B.facets[3]", "'B3'"]),
    "motor: a facet twice in an electrode": (
        MOTOR, [], ['electrodes.common.facets=["inner","guard","sensor","sensor"]'], ["electrodes.common.facets[3]"]),
    "bar: a facet twice in a support": (BAR, [], ['supports=[{facets=["bottom", "bottom"], components=["z"]}]'],
                                        ["supports[0].facets[1]"]),
    "bar: a component twice in a support": (BAR, [], ['supports=[{facets=["bottom"], components=["z", "z"]}]'],
                                            ["supports[0].components[1]"]),
    "bar: r and x, one component": (BAR, [], ['supports=[{facets=["bottom"], components=["r", "x"]}]'],
                                    ["supports[0].components[1]", "'r'"]),
    "bar: two supports hold one component": (
        BAR, [], ['supports=[{facets=["bottom"], components=["z"]}, {facets=["bottom"], components=["r", "z"]}]'],
        ["supports[1].facets[0]", "supports[0]"]),
    "bar: two regions on one cell group": (
        BAR, [], ['regions=[{cells="piezo", material="pzt4"}, {cells="piezo", material="pzt4"}]'],
        ["regions[1].cells"]),
    "strip: two base motions of one name": (STRIP, [], [_motions(("wave", "bottom"), ("wave", "top"))],
                                            ["transient.base_motions[1].name", "'wave'"]),
    "strip: one facet group prescribed twice": (STRIP, [], [_motions(("first", "bottom"), ("second", "bottom"))],
                                                ["transient.base_motions[1].facets", "'bottom'"]),
    "strip: base motions meeting at an edge": (
        STRIP, [], [_motions(("first", "bottom"), ("second", "side"))],
        ["transient.base_motions[1].facets", "shares displacement DOFs with base_motions[0]"]),
    "strip: one contact under two names": (STRIP, [(_SLIDER, _SLIDER_COPY + _SLIDER)], [],
                                           ["transient.contacts[1]", "'strip_slider_again'"]),
    "drill: a body against itself": (FE, [], ['transient.contacts[1].lower="ball"'], ["transient.contacts[1].upper"]),
    # validate makes run's mesh checks (without solving)
    "bar 3d: the wave circle leaves the mesh": (BAR3D, [], [*QUIET, 'analyses=["harmonic"]', _WAVE],
                                                ["harmonic.wave.circle_radius_m", "leaves the mesh"]),
    "bar 3d: the identification circle leaves the mesh": (
        BAR3D, [], [*QUIET, "modal.n_modes=2", "modal.identify={circle_radius_m=0.5, circle_height_m=0.01}"],
        ["modal.identify.circle_radius_m"]),
    # the key at fault
    "stator: sensor2 on the sensor": (STATOR, [], ["geometry.parameters.sensor2_centre_deg=45.0"],
                                      ["geometry.parameters.sensor2_centre_deg", "'sensor' strip"]),
    "motor: sensor2 on the sensor": (MOTOR, [], ["geometry.parameters.sensor2_centre_deg=45.0"],
                                     ["geometry.parameters.sensor2_centre_deg", "'sensor' strip"]),
    "stator: the sensor on an A strip": (STATOR, [], ["geometry.parameters.sensor_centre_deg=0.0"],
                                         ["geometry.parameters.sensor_centre_deg", "'A1' strip"]),
    "stator: B strips on the A strips": (STATOR, [], ["geometry.parameters.phase_shift_deg=10.0"],
                                         ["geometry.parameters.phase_shift_deg", "'A1' strip"]),
    "motor: an end time shorter than one drive period": (
        MOTOR, [], ["transient.end_time_s=1e-5"], ["transient.end_time_s", "one drive period (2.77277e-05 s"]),
    "lumped: a key of the FE tiers' [modal]": (LUMPED, [], ["modal.n_modes=2"],
                                               ["modal: not a section of tier 'lumped'"]),
    "lumped: the FE tiers' [output]": (LUMPED, [], ["output.plots=false"], ["output: not a section of tier 'lumped'"]),
    "bar: a [transient] that only --set makes": (BAR, [], ['analyses=["transient"]', "transient.end_time_s=1e-3"],
                                                ["transient.output_interval_s", "no [transient] section"]),
}


def _shared_dir(tmp_path: Path) -> Path:
    return Path(MPI.COMM_WORLD.bcast(str(tmp_path), root=0))


def _edited(case: Path, edits, directory: Path) -> Path:
    """``case`` with each (old, new) replaced once, written by rank 0 into ``directory`` (None: ``case``)."""
    if not edits:
        return case
    edited = directory / f"edited-{case.name}"
    if MPI.COMM_WORLD.rank == 0:
        text = case.read_text()
        for old, new in edits:
            assert old in text, old
            text = text.replace(old, new, 1)
        edited.write_text(text)
    MPI.COMM_WORLD.barrier()
    return edited


def refused_alike(capsys, argv_of, *fragments) -> None:
    """``validate`` then ``run``: exit 2 on every rank; on rank 0 one line holding ``fragments``, the same from
    both commands, no traceback; nothing from the other ranks. (``validate`` first: an input it misses fails the
    test before ``run`` starts a long simulation.)"""
    lines = []
    for command in ("validate", "run"):
        code, err = cli_main(capsys, *argv_of(command))
        assert code == 2, err
        assert "Traceback" not in err
        if MPI.COMM_WORLD.rank == 0:
            lines.append([line for line in err.splitlines() if line.strip()])
            assert len(lines[-1]) == 1, err
            assert all(f in lines[-1][0] for f in fragments), (fragments, lines[-1][0])
        else:
            assert err == ""
    if lines:
        assert lines[1] == lines[0], f"validate: {lines[0]}, run: {lines[1]}"


@pytest.mark.mpi
@pytest.mark.parametrize("name", list(INPUTS))
def test_refused_alike_by_run_and_validate(capsys, tmp_path, name):
    case, edits, overrides, fragments = INPUTS[name]
    directory = _shared_dir(tmp_path)
    case = _edited(case, edits, directory)
    sets = [a for o in overrides for a in ("--set", o)]

    def argv_of(command):
        return [command, case, *sets, *(["--out", directory / "out", "--quiet"] if command == "run" else [])]

    refused_alike(capsys, argv_of, case.name, *fragments)
    assert not (directory / "out" / "summary.json").exists()


@pytest.mark.mpi
def test_sweep_of_a_key_the_tier_does_not_read(capsys, tmp_path):
    """``sweep cases/usdc-lumped.toml --param modal.n_modes=1,2`` names the section and the --param."""
    out = _shared_dir(tmp_path) / "sweep"
    code, err = cli_main(capsys, "sweep", LUMPED, "--param", "modal.n_modes=1,2", "--out", out, "--quiet")
    assert code == 2, err
    if MPI.COMM_WORLD.rank == 0:
        lines = [line for line in err.splitlines() if line.strip()]
        assert len(lines) == 1, err
        for fragment in (LUMPED.name, "modal: not a section of tier 'lumped'", "--param modal.n_modes=1"):
            assert fragment in lines[0], lines[0]
    assert not (out / "sweep.csv").exists()


def test_stator_wave_circle_is_refused_by_validate(capsys):
    """The issue's own input, on the stator (coarse mesh; ``validate`` only: ``run`` solves the modes first)."""
    from test_bad_input_suite import assert_one_line

    # the coarse swept mesh's chords sag 0.22 mm at the outer wall: the other circles and the generatrix inside
    coarse = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.tip_mesh_size_m=0.003",
              "modal.identify.line_radius_m=0.0132", "modal.identify.circle_radius_m=0.01305",
              "modal.contact_force.circle_radius_m=0.01305", "harmonic.wave.circle_radius_m=0.5"]
    code, err = cli_main(capsys, "validate", STATOR, *[a for o in coarse for a in ("--set", o)])
    if MPI.COMM_WORLD.rank == 0:
        assert_one_line(code, err, STATOR.name, "harmonic.wave.circle_radius_m", "leaves the mesh")


@pytest.mark.parametrize("case, overrides", [
    (BAR, ['analyses=["modal"]', 'electrodes.hot.kind="ground"', 'electrodes.side={facets=["side"], kind="ground"}']),
    (BAR, ['supports=[{facets=["bottom"], components=["z"]}, {facets=["top"], components=["z"]}]']),
    (STRIP, [_motions(("first", "bottom"), ("second", "top"))]),
])
def test_what_may_touch_stays_valid(capsys, case, overrides):
    """Ground electrodes meeting at an edge (all at 0 V), two supports on different facets, two base motions on
    facet groups apart: valid."""
    code, err = cli_main(capsys, "validate", case, *[a for o in overrides for a in ("--set", o)])
    assert code == 0, err


@pytest.mark.parametrize("sensor2_centre_deg", [None, 67.5, 65.6, 69.4])
def test_stator_strips_apart_are_valid(sensor2_centre_deg):
    """The stator's strips may sit anywhere they do not overlap: with the case's 20.5 deg strips the second
    sensor fits between the first (34.75 to 55.25 deg) and A2 (79.75 to 100.25 deg), centred 65.5 to 69.5 deg."""
    from app.case.validate import from_dict
    from geometry.stator import StatorParameters

    layout = {"strip_width_deg": 20.5, "sensor_width_deg": 20.5, "sensor_centre_deg": 45.0,
              "sensor2_centre_deg": sensor2_centre_deg, "guard_width_deg": 20.5}
    params = from_dict(StatorParameters, layout, "case.toml", "geometry.parameters")
    assert len(params.strips()) == 9 + (sensor2_centre_deg is not None)


# repeats and overlaps that the names show: refused when the case is read, before any mesh (the mesh-level
# checks by tag and by DOFs would refuse most of them too, later)
BY_NAME = ["stator: voltage electrodes on one facet group", "motor: ground and voltage electrodes on one facet group",
           "stator: a facet twice in an electrode", "bar: a facet twice in a support",
           "bar: a component twice in a support", "bar: two supports hold one component",
           "bar: two regions on one cell group", "strip: two base motions of one name",
           "strip: one facet group prescribed twice", "strip: one contact under two names",
           "drill: a body against itself", "motor: an end time shorter than one drive period",
           "lumped: a key of the FE tiers' [modal]", "bar: a [transient] that only --set makes"]


@pytest.mark.parametrize("name", BY_NAME)
def test_refused_when_the_case_is_read(tmp_path, name):
    from app.case.schema import load_case
    from app.errors import CaseError

    case, edits, overrides, fragments = INPUTS[name]
    with pytest.raises(CaseError) as err:
        load_case(_edited(case, edits, tmp_path), overrides)
    assert fragments[0].split(":")[0] == err.value.key
