"""Rod impact and ball drop in the modal tier: the FE tier's closed-form checks on the reduced model.

The FE tier's tests (tests/test_transient_rod_impact.py, tests/test_transient_ball.py) build the
scenes with dolfinx and step the full FE equations. Here the same scenes run on the modal tier's
pieces: a Craig-Bampton basis of the same FE model (app.reduced.craig_bampton, interface = every
displacement DOF of the contact facets' nodes), the facet group as sites at its nodes with lumped areas
(app.contact.surface) and the compiled loop (app.reduced.kernel, tests/reduced_scene.py builds its records).

* Rod impact (surface contact against a plane, Saint-Venant): duration 2 L / c and force
  rho c A v0, with the FE tier's tolerances. The wave front is a step: the fixed-interface modes
  kept must carry it, so the error falls as modes are added (test_rod_impact_error_falls_with_modes).
* Ball drop (rigid-rigid Kelvin-Voigt link: the FE tier's scene has no FE part either): duration
  and restitution against the closed form, with the FE tier's tolerances.
* A ball bouncing on an elastic bar's end face (sphere surface contact) from a case file: contact duration,
  peak force, impulse and rebound speed against the FE tier on the same mesh.
The derivatives of the condensed step against finite differences: tests/test_reduced_kernel.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh
from dolfinx.fem.petsc import assemble_matrix
from mpi4py import MPI
from reduced_scene import Body, Contact, Link, bodies_record, contacts_record, hertz_duration_s, run, sites_record

from app.contact import law
from app.contact.surface import surface_nodes
from app.reduced import kernel as kr
from app.reduced.craig_bampton import reduce_model
from demos.demo_ball_drop import BallDrop, ball_drop_closed_form, ball_step_sizes, measured_impact
from demos.demo_rod_impact import RodImpact, contact_pulse, rod_step_sizes
from forms.dynamics import mass
from forms.newmark import TimeScheme
from forms.piezo import elastic_stiffness
from forms.voigt import isotropic_stiffness


def _vector_space(msh, degree: int):
    """Displacement space as a one-field mixed space: the block-size-1 numbering the Craig-Bampton
    reduction of the piezoelectric u-phi space works on."""
    return fem.FunctionSpace(msh, ufl.MixedElement([ufl.VectorElement("Lagrange", msh.ufl_cell(), degree)]))


def _assembled(form):
    A = assemble_matrix(fem.form(form))
    A.assemble()
    return A


def rod_scene(rod: RodImpact, n_modes: int, comm=MPI.COMM_SELF):
    """The FE tier's rod impact (demos/demo_rod_impact.py) reduced: the end face's nodes are the interface and
    the contact's sites (lumped areas), a fixed wall as a plane obstacle -> (K, M, q, v, a, body, sites, contact)."""
    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([rod.length_m, rod.height_m])],
                                [rod.elements_along, 1], cell_type=mesh.CellType.quadrilateral,
                                ghost_mode=mesh.GhostMode.shared_facet)
    W = _vector_space(msh, rod.degree)
    fdim = msh.topology.dim - 1
    end = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], rod.length_m))
    tags = mesh.meshtags(msh, fdim, np.sort(end), np.full(end.size, 1, dtype=np.int32))
    u, w = ufl.split(ufl.TrialFunction(W))[0], ufl.split(ufl.TestFunction(W))[0]
    c = fem.Constant(msh, isotropic_stiffness(rod.young_Pa, 0.0))
    K = _assembled(elastic_stiffness(u, w, c, "plane_strain", ufl.dx(domain=msh)))
    M = _assembled(mass(u, w, fem.Constant(msh, rod.density_kg_per_m3), ufl.dx(domain=msh)))
    nodes = surface_nodes(W, W.sub(0), tags, 1, 1.0, np.zeros(0, np.int32))
    interface = nodes.global_dofs.reshape(-1)
    basis = reduce_model(K, M, None, W, np.zeros(0, np.int32), interface.astype(np.int64), {}, n_modes=n_modes)
    # initial velocity v0 along x everywhere: the M-projection onto the basis
    field = fem.Function(W)
    field.sub(0).interpolate(lambda x: np.vstack([np.full(x.shape[1], rod.speed_m_per_s), np.zeros(x.shape[1])]))
    Mv = M.createVecLeft()
    M.mult(field.vector, Mv)
    v = np.linalg.solve(basis.M, basis.project_vector(Mv))
    K.destroy()
    M.destroy()
    Mv.destroy()
    n = basis.size
    wall = Body(0.0, [rod.length_m + rod.gap_m, 0.0], [False, False])
    contact = Contact(0, law.SURFACE, "plane", (-1.0, 0.0, 0.0), stiffness=rod.penalty_Pa_per_m)
    rows = np.zeros((interface.size, n))
    rows[np.arange(interface.size), np.arange(interface.size)] = 1.0      # sites = the interface nodes
    points = np.zeros((nodes.size, 3))
    points[:, :2] = nodes.coordinates_m
    sites = sites_record(points, nodes.area_m2, np.zeros(nodes.size, np.int64), rows, contacts_record([contact]),
                         bodies_record([wall], 2))
    scene = (basis.K, basis.M, np.zeros((n, n)), np.zeros(n), v, np.zeros(n), wall, sites, contact)
    basis.destroy()
    return scene


def _run_rod(rod: RodImpact, n_modes: int, scheme=None, comm=MPI.COMM_SELF):
    K, M, C, q, v, a, wall, sites, contact = rod_scene(rod, n_modes, comm)
    records, istate = run(K, M, C, q, v, a, [wall], 2, sites, [contact], [],
                          scheme or TimeScheme.generalized_alpha(0.5), rod_step_sizes(rod),
                          1.4 * rod.contact_duration_s)
    for r in records:
        r["contact_force_N"] = {"rod_wall": r["contact_force_N"]["c0"]}
    return records, istate


def _rod_errors(rod, records):
    duration, mean_force, median_force, peak = contact_pulse(records)
    return (abs(duration / rod.contact_duration_s - 1), abs(mean_force / rod.contact_force_N - 1),
            abs(median_force / rod.contact_force_N - 1), peak / rod.contact_force_N)


# Fixed-interface modes kept: 80 of the 160 (40 x 1 bilinear elements, 4 interface DOFs). The pulse
# is a step wave; its plateau needs the axial modes up to the mesh's resolution (median error
# 0.78, 0.23, 0.018, 0.0011 at 10, 20, 40, 80 modes: test_rod_impact_error_falls_with_modes).
ROD_MODES = 80
ROD_ALL_MODES = 156     # SLEPc's shift-invert returns the lowest 156 of the 160 reliably


def test_rod_impact_matches_saint_venant_in_the_modal_tier():
    """The FE tier's checks and tolerances (test_rod_impact_matches_saint_venant)."""
    rod = RodImpact(elements_along=40)
    records, istate = _run_rod(rod, ROD_MODES)
    duration, mean_force, median_force, peak = contact_pulse(records)
    assert duration == pytest.approx(rod.contact_duration_s, rel=0.03)
    assert mean_force == pytest.approx(rod.contact_force_N, rel=0.05)
    assert median_force == pytest.approx(rod.contact_force_N, rel=0.01)
    assert peak < 2.0 * rod.contact_force_N     # the wave-front overshoot of a penalty contact
    assert istate[kr.I_CUTBACKS] == 0
    assert records[-1]["contact_closed"].tolist() == [0]


def test_rod_impact_error_falls_with_modes():
    """Mode truncation is the reduced model's error: the plateau's error falls as modes are added."""
    rod = RodImpact(elements_along=40)
    errors = []
    for n in (10, 20, 40, ROD_MODES):
        records, _ = _run_rod(rod, n)
        errors.append(_rod_errors(rod, records)[2])
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[0] > 0.5 and errors[-1] < 0.002, errors


def test_rod_impact_full_basis_reproduces_the_fe_tier():
    """With (nearly) every mode kept the reduced model is the FE model: the contact force history
    of the FE tier's rod impact step for step (nodal and Gauss quadrature of the penalty agree on
    the flat, uniformly pressed end face)."""
    from app.transient.stepper import run_scene
    from demos.demo_rod_impact import build_rod_impact

    rod = RodImpact(elements_along=40)
    scheme = TimeScheme.generalized_alpha(0.5)
    system, state = build_rod_impact(MPI.COMM_SELF, rod, scheme)
    fe, _, _ = run_scene(system, state, rod_step_sizes(rod), 1.4 * rod.contact_duration_s)
    system.destroy()
    reduced, _ = _run_rod(rod, ROD_ALL_MODES, scheme)
    assert len(reduced) == len(fe)
    np.testing.assert_allclose([r["time_s"] for r in reduced], [r["time_s"] for r in fe], rtol=1e-12)
    force_fe = np.array([r["contact_force_N"]["rod_wall"][0] for r in fe])
    force_reduced = np.array([r["contact_force_N"]["rod_wall"][0] for r in reduced])
    np.testing.assert_allclose(force_reduced, force_fe, atol=1e-4 * rod.contact_force_N)


def test_rod_impact_trapezoidal_rule_in_the_modal_tier():
    """The FE tier's test_rod_impact_trapezoidal_rule_pulse. Duration and impulse pass with its
    tolerances at the default 80 modes. Its plateau check (median within 5 %) needs nearly the
    full basis: without numerical dissipation the contact node rattles on the penalty wherever the
    truncation stiffens its neighbourhood (median 56 %, 18 %, 2 % low at 80, 120, 156 modes; the
    dissipative scheme, the case default, needs 80: test_rod_impact_error_falls_with_modes)."""
    rod = RodImpact(elements_along=40)
    medians = []
    for n in (ROD_MODES, 120, ROD_ALL_MODES):
        records, istate = _run_rod(rod, n, TimeScheme.newmark())
        duration, mean_force, median_force, _ = contact_pulse(records)
        assert duration == pytest.approx(rod.contact_duration_s, rel=0.03)
        assert mean_force == pytest.approx(rod.contact_force_N, rel=0.05)
        assert istate[kr.I_CUTBACKS] == 0
        medians.append(abs(median_force / rod.contact_force_N - 1))
    assert medians[0] > medians[1] > medians[2], medians
    assert medians[-1] < 0.05, medians


def test_rod_impact_with_1000x_penalty_in_the_modal_tier():
    """The FE tier's test_rod_impact_with_1000x_penalty_finishes (20 elements: 80 interior DOFs)."""
    rod = RodImpact(elements_along=20, penalty_factor=10.0 * 1000)
    records, istate = _run_rod(rod, 60)
    duration, mean_force, _, _ = contact_pulse(records)
    assert duration == pytest.approx(rod.contact_duration_s, rel=0.10)
    assert mean_force == pytest.approx(rod.contact_force_N, rel=0.10)
    assert istate[kr.I_STEPS] > 0


# ---------------------------------------------------------------- ball drop (rigid-rigid link)
def _drop(ball: BallDrop):
    """demos/demo_ball_drop.py's scene: ground (fixed) and ball, 1D vertical, no structure."""
    fall_s = np.sqrt(2 * ball.height_m / ball.gravity_m_per_s2)
    duration_cf, restitution_cf = ball_drop_closed_form(ball)
    ground = Body(0.0, [0.0], [False])
    falling = Body(ball.mass_kg, [ball.height_m + ball.diameter_m / 2], [True],
                   load_N=[-ball.mass_kg * ball.gravity_m_per_s2])
    link = Link(0, 1, (1.0, 0.0, 0.0), ball.diameter_m / 2, ball.stiffness_N_per_m, ball.damping_N_s_per_m)
    empty = np.zeros((0, 0))
    records, istate = run(empty, empty, empty, [], [], [], [ground, falling], 1, None, [], [link],
                          TimeScheme.newmark(), ball_step_sizes(ball), fall_s + 3 * duration_cf)
    for r in records:
        r["contact_force_N"] = {"ground_ball": r["contact_force_N"]["c0"]}
    return measured_impact(ball, records), (duration_cf, restitution_cf), istate


@pytest.mark.parametrize("stiffness_factor", [1.0, 1000.0])
def test_ball_drop_matches_kelvin_voigt_closed_form_in_the_modal_tier(stiffness_factor):
    """The FE tier's test_ball_drop_matches_kelvin_voigt_closed_form, tolerances included."""
    base = BallDrop()
    ball = dataclasses.replace(base, stiffness_N_per_m=base.stiffness_N_per_m * stiffness_factor,
                               damping_N_s_per_m=base.damping_N_s_per_m * np.sqrt(stiffness_factor))
    (duration, restitution), (duration_cf, restitution_cf), istate = _drop(ball)
    assert duration == pytest.approx(duration_cf, rel=0.005)
    assert restitution == pytest.approx(restitution_cf, abs=0.002)
    assert restitution < 0.995
    assert istate[kr.I_CUTBACKS] == 0


def test_ball_drop_without_damping_rebounds_fully_in_the_modal_tier():
    ball = BallDrop(damping_N_s_per_m=0.0)
    (duration, restitution), (duration_cf, restitution_cf), _ = _drop(ball)
    assert restitution_cf == pytest.approx(1.0, abs=1e-9)
    assert restitution == pytest.approx(1.0, abs=2e-3)
    assert duration == pytest.approx(duration_cf, rel=0.01)


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="compares a parallel reduction with a serial one")
def test_rod_impact_modal_tier_parallel_equals_serial():
    """The facet nodes, their lumped areas and the basis built on the FE partition (2 ranks) give
    the serial pulse step for step."""
    rod = RodImpact(elements_along=40)
    parallel, _ = _run_rod(rod, ROD_MODES, comm=MPI.COMM_WORLD)
    serial, _ = _run_rod(rod, ROD_MODES, comm=MPI.COMM_SELF)
    assert len(parallel) == len(serial)
    np.testing.assert_allclose([r["time_s"] for r in parallel], [r["time_s"] for r in serial], rtol=1e-12)
    f_p = np.array([r["contact_force_N"]["rod_wall"][0] for r in parallel])
    f_s = np.array([r["contact_force_N"]["rod_wall"][0] for r in serial])
    np.testing.assert_allclose(f_p, f_s, rtol=1e-7, atol=1e-7 * rod.contact_force_N)


# ---------------------------------------------------------------- a case file, both tiers
BALL_ON_BAR = """
title = "steel ball on a steel bar's end face (sphere surface contact)"
tier = "fe"
analyses = ["transient"]

[geometry]
model = "plane_strain"
builder = "bar"
parameters = { length_m = 0.02, width_m = 0.002, axial_divisions = 10, lateral_divisions = 16 }
degree = 2
thickness_m = 0.001

[materials.steel]
library = "structural-steel"

[[regions]]
cells = "piezo"
material = "steel"

[[supports]]
facets = ["bottom"]
components = ["x", "z"]

[points.end]
coordinates_m = [0.0, 0.02]
component = "z"

[output]
fields = false
plots = false

[damping]
material_quality = false

[transient]
end_time_s = 1.6e-4
output_interval_s = 1.6e-4

[transient.steps]
open_s = 1e-6
closed_s = 2.5e-7
change_s = 6.25e-8

[[transient.bodies]]
name = "ball"
position_m = [0.0003, 0.024001]
mass_kg = 0.002
velocity_m_per_s = [0.0, -0.5]
free_axes = [false, true]

[[transient.contacts]]
name = "bar_ball"
kind = "surface"
facets = "top"
body = "ball"
shape = "sphere"
radius_m = 0.004
stiffness = 1e13
"""


def _impact(directory):
    import h5py

    with h5py.File(directory / "transient.h5", "r") as f:
        t, force = f["time_s"][:], f["bar_ball_force_N"][:, 1]
        closed, velocity = f["bar_ball_closed"][:] > 0, f["ball_velocity_m_per_s"][:, 1]
    rows = np.flatnonzero(closed)
    return {"duration_s": t[rows[-1]] - t[rows[0]], "peak_N": np.abs(force).max(), "rebound_m_per_s": velocity[-1],
            "impulse_N_s": np.trapz(force, t)}


def test_ball_on_bar_case_modal_tier_matches_the_fe_tier(tmp_path):
    """A case file with a sphere surface contact (a 2 g ball at 0.5 m/s on a steel bar's P2 end
    face, 16 elements across) run in both tiers: contact duration, peak force, impulse and
    rebound speed agree. The difference is the contact integration (nodes with lumped areas
    against Gauss points of the facets; the basis is converged: 9 and 150 modes agree to 4 digits)
    and falls with the contact mesh: 0.5, 0.6, 0.5, 1.0 % at 8 elements across, 0.2, 0.3, 0.05,
    0.1 % at 16."""
    from conftest import run_case_quiet

    case = tmp_path / "ball-on-bar.toml"
    case.write_text(BALL_ON_BAR)
    run_case_quiet(case, tmp_path / "fe")
    modal = run_case_quiet(case, tmp_path / "modal", 'tier="modal"')
    assert modal["results"]["transient"]["reduction"]["interface_dofs"] == 2 * 33      # 16 P2 facets
    reference, reduced = _impact(tmp_path / "fe"), _impact(tmp_path / "modal")
    assert reduced["duration_s"] == pytest.approx(reference["duration_s"], rel=0.005)
    assert reduced["peak_N"] == pytest.approx(reference["peak_N"], rel=0.01)
    assert reduced["impulse_N_s"] == pytest.approx(reference["impulse_N_s"], rel=0.005)
    assert reduced["rebound_m_per_s"] == pytest.approx(reference["rebound_m_per_s"], rel=0.005)
    assert 0.4 < reduced["rebound_m_per_s"] < 0.5         # it bounced, leaving energy in the bar


def test_lumped_areas_are_positive_and_sum_to_the_area():
    """P1 facets: the row sums of the facet mass matrix (the consistent nodal forces of a uniform
    pressure). P2 triangles (3D): the row sums are zero at the vertices, so HRZ: positive, the
    same total area, vertex : edge ratio 6 : 32 (the diagonal of the P2 triangle mass matrix)."""
    msh = mesh.create_unit_cube(MPI.COMM_SELF, 2, 2, 2)
    fdim = 2
    top = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[2], 1.0))
    tags = mesh.meshtags(msh, fdim, np.sort(top), np.full(top.size, 1, dtype=np.int32))
    for degree, lumping in ((1, "row sum"), (2, "HRZ")):
        W = _vector_space(msh, degree)
        nodes = surface_nodes(W, W.sub(0), tags, 1, 1.0, np.zeros(0, np.int32))
        assert nodes.lumping == lumping
        assert np.all(nodes.area_m2 > 0)
        assert nodes.area_m2.sum() == pytest.approx(1.0, rel=1e-12)
        assert nodes.size == (3 if degree == 1 else 5) ** 2
        assert np.all(nodes.global_dofs >= 0) and np.unique(nodes.global_dofs).size == 3 * nodes.size
    # the last (P2) areas: the face's corner vertex lies in one or two of its 8 triangles (area 1/8,
    # by the diagonal's direction) and gets 6 / 114 of each
    corner = np.flatnonzero(np.all(np.isclose(nodes.coordinates_m[:, :2], 0.0), axis=1))[0]
    assert np.isclose(nodes.area_m2[corner], [0.125 * 6 / 114, 0.25 * 6 / 114], rtol=1e-12, atol=0).any()


# ---------------------------------------------------------------- damped contact: the energy it takes
#: (kind, damping): a surface penalty (Pa/m, area 1e-6 m^2) with c = 2 zeta sqrt(k A m) / A at zeta = 0, 0.1, 0.3,
#: and a Hertz-like node law k d^1.5 (1e10 N/m^1.5) with 40 and 120 N s/m (zeta about 0.12 and 0.37 on its secant
#: stiffness at the deepest point)
DAMPED_BOUNCES = [(law.SURFACE, 0.0), (law.SURFACE, 0.1), (law.SURFACE, 0.3), (law.NODE, 40.0), (law.NODE, 120.0)]


@pytest.mark.parametrize("kind, damping_parameter", DAMPED_BOUNCES)
def test_damped_contact_dissipates_what_the_bounce_loses_in_the_modal_tier(kind, damping_parameter):
    """A point mass (one contact site, its displacement the structure's two coordinates) bounces off a fixed plane
    through a Kelvin-Voigt contact. Once the site is open again, the kinetic energy the mass lost is what the
    contact's dissipated energy (``dissipated``: damping and friction) says, including the elastic energy the law
    still held when its force k d^e + c dd/dt clipped to zero before the gap opened (a Kelvin-Voigt contact lets go
    while still penetrated; on the surface law that clipped part is 2.1 % of the impact energy at zeta = 0.1 and
    7.3 % at 0.3, which the count missed until 2026-11-27). Reference: the mass's own kinetic energy before and
    after (K = 0, no other loss). Tolerance 1e-4 of the impact energy: Newmark's average-acceleration rule is
    energy-exact for the linear law, and 320 steps per contact leave the law's kink at first touch, the clip and
    the node law's curvature a few 1e-5 at most (measured: 2.2e-5 surface, below 1e-5 node)."""
    mass_kg, speed_m_per_s, wall_gap_m = 1e-3, 1.0, 1e-7
    if kind == law.SURFACE:
        area_m2, k = 1e-6, 1e13
        damping = 2 * damping_parameter * np.sqrt(k * area_m2 * mass_kg) / area_m2
        duration_s = np.pi * np.sqrt(mass_kg / (k * area_m2))
        contact = Contact(0, law.SURFACE, "plane", (-1.0, 0.0, 0.0), stiffness=k, damping=damping)
    else:
        area_m2, k = 1.0, 1e10
        duration_s = hertz_duration_s(mass_kg, k, speed_m_per_s)
        contact = Contact(0, law.NODE, "plane", (-1.0, 0.0, 0.0), stiffness=k, damping=damping_parameter,
                          exponent=1.5)
    wall = Body(0.0, [wall_gap_m, 0.0], [False, False])
    sites = sites_record(np.zeros((1, 3)), np.array([area_m2]), np.zeros(1, np.int64), np.eye(2),
                         contacts_record([contact]), bodies_record([wall], 2))
    dt = duration_s / 320
    final = []
    records, istate = run(np.zeros((2, 2)), mass_kg * np.eye(2), np.zeros((2, 2)), np.zeros(2),
                          np.array([speed_m_per_s, 0.0]), np.zeros(2), [wall], 2, sites, [contact], [],
                          TimeScheme.newmark(), kr.Control(dt, dt, dt, dt / 64, 2.0),
                          wall_gap_m / speed_m_per_s + 1.5 * duration_s, final=final)
    assert records[-1]["contact_closed"].tolist() == [0] and any(r["contact_closed"][0] for r in records)
    rebound = final[0].v[0]
    assert rebound < 0.0                                   # it bounced
    impact_J = 0.5 * mass_kg * speed_m_per_s**2
    lost_J = impact_J - 0.5 * mass_kg * rebound**2
    assert records[-1]["dissipated_J"]["c0"] == pytest.approx(lost_J, abs=1e-4 * impact_J)
    if damping_parameter > 0:
        assert lost_J > 0.1 * impact_J
