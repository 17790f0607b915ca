"""The rigid bodies drawn with their shapes (app/transient/body_shapes.py) from the shipped cases' body and
contact data: the drill's ball, stem and rock in the axisymmetric section, the motor's rotor as a closed conical
disc in 3D, and their motion (translation and rotation) from the packed body coordinates. References are the
case data themselves (radii, touch distances, the cone's angle) and exact geometry; tolerances are round-off."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from conftest import CASES

from app.case.schema import load_case
from app.transient.body_shapes import MERIDIAN, BodyMeshes


def _vertices(meshes: BodyMeshes, name: str) -> np.ndarray:
    index = meshes.names.index(name)
    return meshes.points[np.unique(meshes.triangles[meshes.body == index])]


def _area(points: np.ndarray, triangles: np.ndarray) -> float:
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def test_drill_bodies_in_the_axisymmetric_section():
    case = load_case(CASES / "usdc-fe.toml")
    slices = {"ball": slice(0, 2), "stem": slice(2, 4), "rock": slice(4, 6)}
    meshes = BodyMeshes(case.transient, case.geometry.model, slices, 0.2)
    assert meshes.names == ["ball", "stem", "rock"]
    assert np.all(meshes.points[:, 0] >= 0) and np.all(meshes.points[:, 2] == 0)     # the r >= 0 half, z = 0
    # the ball: the half-disc of the tip_ball contact's radius about its reference point; its polygon's area is
    # the inscribed polygon's, MERIDIAN segments over pi
    r, centre = 0.004, np.array([0.0, -0.00401, 0.0])
    ball = _vertices(meshes, "ball")
    assert np.linalg.norm(ball - centre, axis=1).max() == pytest.approx(r, rel=1e-12)
    ball_cells = meshes.triangles[meshes.body == 0]
    assert _area(meshes.points, ball_cells) == pytest.approx(MERIDIAN * 0.5 * r**2 * np.sin(np.pi / MERIDIAN),
                                                             rel=1e-12)
    # the stem: a rod from its top face down to the rock surface (touch_distance_m = 0.1), as thick as the ball
    stem = _vertices(meshes, "stem")
    np.testing.assert_allclose([stem[:, 0].min(), stem[:, 0].max(), stem[:, 1].min(), stem[:, 1].max()],
                               [0.0, r, -0.10802, -0.00802], rtol=0, atol=1e-15)
    # the rock: a slab whose top is its surface, half the scene wide
    rock = _vertices(meshes, "rock")
    assert rock[:, 1].max() == pytest.approx(-0.10802, abs=1e-15) and rock[:, 0].max() == pytest.approx(0.1)
    # motion: translations move every vertex of the body alike, the rock stays
    z = np.array([0.0, -0.00401 - 1e-4, 0.0, -0.00802 + 2e-5, 0.0, -0.10802])
    u = meshes.displacement(z)
    for name, dz in (("ball", -1e-4), ("stem", 2e-5), ("rock", 0.0)):
        vertices = np.unique(meshes.triangles[meshes.body == meshes.names.index(name)])
        np.testing.assert_allclose(u[vertices], np.tile([0.0, dz, 0.0], (len(vertices), 1)), rtol=0, atol=1e-15)
    assert not meshes.displacement(None).any()


def test_motor_rotor_is_a_closed_conical_disc_that_turns():
    case = load_case(CASES / "wwusm-motor.toml")
    contact = case.transient.contacts[0]
    meshes = BodyMeshes(case.transient, case.geometry.model, {"rotor": slice(0, 4)}, 0.06)
    assert meshes.names == ["rotor"]
    # closed: every edge belongs to exactly two triangles
    edges = Counter(tuple(sorted((tri[a], tri[b]))) for tri in meshes.triangles for a, b in ((0, 1), (1, 2), (2, 0)))
    assert set(edges.values()) == {2}
    # the rim lies on the contact's cone: radius R at the reference height, growing with tan(half angle) along z
    reference = np.array(case.transient.bodies[0].position_m)
    rho = np.hypot(meshes.points[:, 0], meshes.points[:, 1])
    s = meshes.points[:, 2] - reference[2]
    rim = rho > 1e-9
    np.testing.assert_allclose(rho[rim], contact.radius_m + s[rim] * np.tan(np.radians(contact.half_angle_deg)),
                               rtol=1e-12)
    assert set(np.unique(meshes.sector)) == {0, 1}                 # stripes that show the spin
    # a quarter turn about z and a lift: x -> y, every vertex
    lift, angle = 3e-5, np.pi / 2
    z = np.array([0.0, 0.0, reference[2] + lift, angle])
    moved = meshes.points + meshes.displacement(z)
    expected = np.column_stack([-meshes.points[:, 1], meshes.points[:, 0], meshes.points[:, 2] + lift])
    np.testing.assert_allclose(moved, expected, rtol=0, atol=1e-15)
    # a batch of frames at once (the field output's): the quarter turn, a half turn (x -> -x, y -> -y) with
    # another lift, the start
    half = np.array([0.0, 0.0, reference[2] - lift, np.pi])
    start = np.array([0.0, 0.0, reference[2], 0.0])
    batch = meshes.points + meshes.displacements(np.array([z, half, start]))
    np.testing.assert_allclose(batch[0], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(batch[1], meshes.points * [-1, -1, 1] - [0, 0, lift], rtol=0, atol=1e-15)
    np.testing.assert_allclose(batch[2], meshes.points, rtol=0, atol=1e-15)


def test_plane_obstacle_is_a_slab_on_its_side_of_the_plane():
    """The strip friction drive (plane strain): the slider's plane contact, outward normal (0, -1) towards the
    strip, is drawn as a slab above its reference point, both halves (no axis), as wide as the scene."""
    case = load_case(CASES / "validation" / "strip-friction-drive.toml")
    (body,) = case.transient.bodies
    scene = 0.01
    meshes = BodyMeshes(case.transient, case.geometry.model, {body.name: slice(0, 2)}, scene)
    x, y = meshes.points[:, 0] - body.position_m[0], meshes.points[:, 1] - body.position_m[1]
    assert y.min() == pytest.approx(0.0, abs=1e-18) and y.max() == pytest.approx(scene / 4, rel=1e-12)
    assert x.min() == pytest.approx(-scene / 2, rel=1e-12) and x.max() == pytest.approx(scene / 2, rel=1e-12)
    assert _area(meshes.points, meshes.triangles) == pytest.approx(scene * scene / 4, rel=1e-12)
