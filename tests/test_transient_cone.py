"""A rigid cone in a conical funnel (app/transient/contact.py, shape "cone"), the viscous brake on a
free rotation (app/transient/rigid.py) and the steady-state stop (app/loop/steady.py).

The funnel is a steel washer whose inner face is a 15 deg cone 0.3 mm high (the motor's wedge face
in miniature); the rigid cone, free to move along its axis only, is pressed in by a dead load P and
spun at a prescribed rate. Once the contact slides circumferentially, friction has no axial
component and the axial balance of the cone gives the total normal force N = P / sin(alpha); the
friction torque is mu N r_c at the contact radius r_c (the face's radius spread, 0.3 mm x tan 15 deg
= 0.08 mm at r_c = 5.04 mm, bounds the torque to +-0.8 %; the pressure centre is close to mid-height,
0.5 % is asked). The surface speed (0.5 m/s) is 5000 times the friction regularisation speed, so
friction is kinetic to 2e-8. The cone lands from a 6 um radial clearance; contact damping settles
it within a few periods, and the steady-state stop ends the run on the cycle-mean torque."""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from app.case.schema import load_case
from app.runner import run_transient_analysis

ALPHA_DEG, MU, PRELOAD_N, SPIN_RAD_PER_S = 15.0, 0.3, 1.0, 100.0
INNER_RADIUS_M, OUTER_RADIUS_M, HEIGHT_M = 0.005, 0.0065, 0.0003
# the cone's reference point at the face's mid-height, its radius 10 um short of the face there (more
# than the faceted face sags inwards between its nodes)
REFERENCE_Z_M = 0.5 * HEIGHT_M
FACE_RADIUS_M = INNER_RADIUS_M + REFERENCE_Z_M * math.tan(math.radians(ALPHA_DEG))
CLEARANCE_M = 6e-6
CONE_RADIUS_M = FACE_RADIUS_M - CLEARANCE_M


def write_washer_mesh(path, mesh_size_m: float = 0.0005) -> None:
    """A steel washer about z: outer cylinder r = 6.5 mm, inner face a cone of half angle 15 deg from
    r = 5 mm at z = 0 (radius growing with z), 0.3 mm high. Facet groups: funnel, bottom, top, outer."""
    import gmsh

    from geometry.meshdata import GmshSession

    with GmshSession(MPI.COMM_SELF, "washer"):
        occ = gmsh.model.occ
        top_radius = INNER_RADIUS_M + HEIGHT_M * math.tan(math.radians(ALPHA_DEG))
        outer = occ.addCylinder(0, 0, 0, 0, 0, HEIGHT_M, OUTER_RADIUS_M)
        inner = occ.addCone(0, 0, -1e-5, 0, 0, HEIGHT_M + 2e-5,
                            INNER_RADIUS_M - 1e-5 * math.tan(math.radians(ALPHA_DEG)),
                            top_radius + 1e-5 * math.tan(math.radians(ALPHA_DEG)))
        volume = occ.cut([(3, outer)], [(3, inner)])[0][0][1]
        occ.synchronize()
        faces = {"funnel": [], "bottom": [], "top": [], "outer": []}
        for _, face in gmsh.model.getBoundary([(3, volume)], oriented=False):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, face)
            if z1 - z0 < 1e-3 * HEIGHT_M:
                faces["bottom" if z0 < 0.5 * HEIGHT_M else "top"].append(face)
            else:
                faces["funnel" if x1 < 0.5 * (top_radius + OUTER_RADIUS_M) else "outer"].append(face)
        gmsh.model.addPhysicalGroup(3, [volume], 1)
        gmsh.model.setPhysicalName(3, 1, "washer")
        for tag, (name, ids) in enumerate(faces.items(), start=1):
            gmsh.model.addPhysicalGroup(2, ids, tag)
            gmsh.model.setPhysicalName(2, tag, name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size_m)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
        gmsh.option.setNumber("Mesh.MeshSizeMax", 1e22)     # gmsh's default, for later meshes


CASE = """
title = "rigid cone in a conical funnel"
tier = "fe"
analyses = ["transient"]

[geometry]
model = "3d"
mesh_file = "washer.msh"
degree = 1

[materials.steel]
library = "stainless-steel"

[[regions]]
cells = "washer"
material = "steel"

# held at its outer face: a support on the funnel's nodes would take their share of the contact
# force off the cone's equations (the constrained rows of the contact residual are zeroed)
[[supports]]
facets = ["outer"]
components = ["x", "y", "z"]

[damping]
material_quality = false
beta_s = 2e-8

[output]
fields = false
plots = false

[transient]
end_time_s = {end_time}
output_interval_s = 1e-5
initial_state = "rest"
checkpoint_interval_steps = {checkpoint_every}

[transient.drive]
frequency_Hz = 1e5

[transient.steps]
open_s = 5e-7
closed_s = 5e-7
change_s = 5e-7

[transient.steady_state]
body = "cone"
window_cycles = 5
relative_tolerance = 1e-3
min_cycles = 10

[[transient.bodies]]
name = "cone"
position_m = [0.0, 0.0, {z_ref}]
mass_kg = 1e-5
free_axes = [false, false, true]
applied_force_N = [0.0, 0.0, -{preload}]

[[transient.bodies.rotations]]
axis = "z"
{rotation}

[[transient.contacts]]
name = "funnel"
kind = "surface"
facets = "funnel"
body = "cone"
shape = "cone"
axis = [0.0, 0.0, 1.0]
radius_m = {radius}
half_angle_deg = {alpha}
stiffness = 1e13
damping = 3e7

[transient.contacts.friction]
mu_dynamic = {mu}
"""


def make_case(folder, end_time_s: float, rotation: str, checkpoint_every: int = 0):
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
        if not (folder / "washer.msh").exists():
            write_washer_mesh(folder / "washer.msh")
        (folder / "case.toml").write_text(CASE.format(
            end_time=end_time_s, checkpoint_every=checkpoint_every, z_ref=REFERENCE_Z_M, preload=PRELOAD_N,
            rotation=rotation, radius=CONE_RADIUS_M, alpha=ALPHA_DEG, mu=MU))
    comm.barrier()
    return load_case(folder / "case.toml")


def series(out) -> dict:
    with h5py.File(out / "transient.h5", "r") as f:
        return {k: f[k][()] for k in f}


SPIN = f'motion = "constant_rate"\nrate_rad_per_s = {SPIN_RAD_PER_S}'


@pytest.fixture(scope="module")
def spun(tmp_path_factory):
    """(folder, results) of the cone spun in the funnel until the steady-state stop."""
    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(str(tmp_path_factory.mktemp("spin")) if comm.rank == 0 else None, root=0))
    case = make_case(folder, 2e-3, SPIN)
    return folder, case, run(case, folder / "out", comm, lambda *args: None)


@pytest.mark.mpi
def test_cone_pressed_into_a_funnel_carries_p_over_sin_alpha_and_mu_n_r_torque(spun):
    folder, case, results = spun
    steady = results["steady_state"]
    # the steady-state stop ends the run long before end_time_s, on the contact torque
    assert steady["steady"] and steady["watched"] == "torque"
    assert results["simulated_time_s"] < 0.5 * case.transient.end_time_s
    assert steady["cycles"] >= 10
    assert results["cutbacks"] <= 5                             # the landing, if any
    if MPI.COMM_WORLD.rank != 0:
        return
    data = series(folder / "out")
    alpha = math.radians(ALPHA_DEG)
    last = data["time_s"] > data["time_s"][-1] - 1e-5           # the last period
    force = data["funnel_force_N"][last]                         # on the cone
    torque = data["funnel_torque_N_m"][last, 0]
    # axially the contact carries the preload (the cone is at rest along its axis); sideways it
    # does not cancel exactly: the faceted funnel is not round, the cone's centre is held
    np.testing.assert_allclose(force[:, 2], PRELOAD_N, rtol=1e-3)
    normal_force = PRELOAD_N / math.sin(alpha)
    # friction drags the cone along the funnel's (zero) surface velocity: against its spin
    np.testing.assert_allclose(-torque, MU * normal_force * FACE_RADIUS_M, rtol=5e-3)
    assert steady["cycle_mean_torque_N_m"] == pytest.approx(np.mean(torque), rel=1e-3)
    assert 0 < REFERENCE_Z_M - data["cone_position_m"][-1, 2] < CLEARANCE_M / math.tan(alpha)   # it sank in


@pytest.mark.mpi
def test_steady_state_stop_resumes_from_its_checkpoint_like_the_uninterrupted_run(spun, shared_tmp):
    """The cycle means live in the checkpoint: a run stopped before steady state and resumed stops
    at the same period with the same means as one that ran through."""
    comm = MPI.COMM_WORLD
    _, case, through = spun
    t_stop = through["simulated_time_s"]
    dt = case.transient.steps.closed_s
    folder = shared_tmp / "parts"
    first = run(make_case(folder, dt * round(0.5 * t_stop / dt), SPIN, checkpoint_every=7), folder / "out", comm,
                lambda *args: None)
    assert not first["steady_state"]["steady"]
    resumed = run(make_case(folder, 2e-3, SPIN, checkpoint_every=7), folder / "out", comm, lambda *args: None,
                  resume=True)
    assert resumed["steady_state"]["steady"]
    assert resumed["steady_state"]["cycles"] == through["steady_state"]["cycles"]
    np.testing.assert_allclose(resumed["steady_state"]["cycle_means"], through["steady_state"]["cycle_means"],
                               rtol=1e-5)
    assert abs(resumed["simulated_time_s"] - t_stop) <= dt      # (the landing's cut-backs put steps off the grid)


@pytest.mark.mpi
def test_a_cone_not_about_the_rotation_axis_is_refused(shared_tmp):
    """A cone spun about another axis than its own is not a body of revolution about it: its gap would
    change with the angle, which the contact does not model. Refused when the case is read (every tier)."""
    from app.errors import CaseError

    comm = MPI.COMM_WORLD
    folder = shared_tmp / "tilted"
    make_case(folder, 2e-3, SPIN)
    if comm.rank == 0:
        text = (folder / "case.toml").read_text().replace("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.6, 0.8]")
        (folder / "case.toml").write_text(text)
    comm.barrier()
    with pytest.raises(CaseError) as err:
        load_case(folder / "case.toml")
    assert err.value.key == "transient.contacts[0].axis"
    assert "not a body of revolution" in str(err.value)


# ---------------------------------------------------------------- exclude_initial_gap (ANSYS KEYOPT(9) = 1)
# The cone sits exactly on the design face (no clearance), on a coarse washer (1 mm elements, P1): the
# straight facets sag by up to h^2/(8 r) ~ 25 um inside the design cone, so without the option the cone
# overlaps the funnel at rest. The penalty is soft (1e11 Pa/m) against the washer (its radial give adds
# 0.24 %), so the penetration is the penalty's: N / (k A) with A the funnel's area, 3.9 um, uniform round
# the ring because the faceting is excluded, and the cone sinks by that / sin(alpha).
SOFT_PENALTY_PA_PER_M, SOFT_DAMPING_PA_S_PER_M = 1e11, 1.2e6     # ~0.5 of critical for the cone's axial mode
FUNNEL_AREA_M2 = (math.pi * (2 * INNER_RADIUS_M + HEIGHT_M * math.tan(math.radians(ALPHA_DEG)))
                  * HEIGHT_M / math.cos(math.radians(ALPHA_DEG)))


def make_design_case(folder, end_time_s: float, preload_n: float, exclude: bool):
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
        if not (folder / "washer.msh").exists():
            write_washer_mesh(folder / "washer.msh", mesh_size_m=0.001)
        text = CASE.format(end_time=end_time_s, checkpoint_every=0, z_ref=REFERENCE_Z_M, preload=preload_n,
                           rotation=SPIN, radius=FACE_RADIUS_M, alpha=ALPHA_DEG, mu=MU)
        text = text.replace("stiffness = 1e13\ndamping = 3e7",
                            f"stiffness = {SOFT_PENALTY_PA_PER_M}\ndamping = {SOFT_DAMPING_PA_S_PER_M}\n"
                            f"exclude_initial_gap = {'true' if exclude else 'false'}")
        (folder / "case.toml").write_text(text)
    comm.barrier()
    return load_case(folder / "case.toml")


@pytest.mark.mpi
def test_excluded_initial_gap_leaves_a_faceted_funnel_unloaded_at_rest(shared_tmp):
    """Zero load on the design cone: no force at any step with the option; without it the facets'
    sag overlaps the cone and the first step already carries a large force."""
    comm = MPI.COMM_WORLD
    forces = {}
    for exclude in (True, False):
        folder = shared_tmp / f"rest_{exclude}"
        case = make_design_case(folder, 1e-5, 0.0, exclude)
        run(case, folder / "out", comm, lambda *args: None)
        if comm.rank == 0:
            data = series(folder / "out")
            forces[exclude] = np.abs(data["funnel_force_N"]).max()
            if exclude:
                assert np.all(data["cone_position_m"][:, 2] == REFERENCE_Z_M)
    if comm.rank == 0:
        assert forces[True] == 0.0
        assert forces[False] > 1.0            # the overlap alone pushes harder than the test's 1 N preload


@pytest.mark.mpi
def test_excluded_initial_gap_on_a_faceted_funnel_gives_p_over_sin_alpha_and_the_penalty_penetration(shared_tmp):
    comm = MPI.COMM_WORLD
    folder = shared_tmp / "design"
    case = make_design_case(folder, 2e-3, PRELOAD_N, True)
    results = run(case, folder / "out", comm, lambda *args: None)
    assert results["steady_state"]["steady"]
    if comm.rank != 0:
        return
    data = series(folder / "out")
    alpha = math.radians(ALPHA_DEG)
    last = data["time_s"] > data["time_s"][-1] - 1e-5
    np.testing.assert_allclose(data["funnel_force_N"][last, 2], PRELOAD_N, rtol=1e-3)
    normal_force = PRELOAD_N / math.sin(alpha)
    np.testing.assert_allclose(-data["funnel_torque_N_m"][last, 0], MU * normal_force * FACE_RADIUS_M, rtol=5e-3)
    # the integral of the pressure (the new time-series column) is that same N
    np.testing.assert_allclose(data["funnel_normal_force_N"][last], normal_force, rtol=1e-3)
    # the whole faceted funnel carries it (without the option only the facet middles would) ...
    assert np.all(data["funnel_area_in_contact_m2"][last] > 0.99 * FUNNEL_AREA_M2)
    # ... with the penalty's uniform penetration: the cone's sink times sin(alpha), which also holds the
    # washer's small radial give (measured +0.24 %)
    penetration = (REFERENCE_Z_M - data["cone_position_m"][last, 2].mean()) * math.sin(alpha)
    np.testing.assert_allclose(penetration, normal_force / (SOFT_PENALTY_PA_PER_M * FUNNEL_AREA_M2), rtol=0.01)


def run(case, out_dir, comm, log, resume=False):
    """The case's transient analysis through the one run loop (the FE tier's engine), as ``piezodyn run`` does."""
    out_dir = Path(out_dir)
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    return run_transient_analysis(case, out_dir, comm, log, resume)
