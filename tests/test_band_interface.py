"""The band interface of a ring-sampled contact (``reduction.interface = "band"``, app/contact/sites.py).

References and tolerances:
- the band's patterns and the sites' rows are one interpolation (cubic Lagrange in angle of the cylindrical
  components, linear in height between the band's two edges): at the same points they agree to round-off (1e-12);
- at a station the pattern is the unit displacement of that station's DOF (Lagrange weights): exactly 1 and 0;
- a rigid translation interpolated from 32 stations per edge: cubic interpolation of cos/sin with a step of
  2 pi / 32 errs by about (2 pi / 32)^4 / 128 ~ 1e-5, checked at 1e-4;
- the reduced stator (the tests' coarse mesh): every basis vector's displacement at the band's vertices is the
  interpolation of its station values (1e-9 of the largest entry: the static solves' round-off); the band only
  constrains the stator, so its F(1,4) lies above the free-band one (Rayleigh), by less than 1 % (measured +0.37 %
  at 32 stations per edge: a designer's "contact face moves as a ring" idealisation must stay small).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CASES

from app.contact.sites import cylindrical_frames, in_plane_basis, ring_band_patterns, ring_interface_rows

MOTOR = CASES / "wwusm-motor.toml"
# the coarse stator of tests/test_motor_preloads.py: its free-band ("nodes") reduced model is the one those tests build
COARSE = ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
          "reduction.interface_nodes=32", "transient.contacts[0].sample_points=128", "transient.end_time_s=0.004",
          "output.plots=false"]


def _synthetic_ring(per_edge=32, band_nodes=96, seed=3):
    """Two edges of a band (heights 0 and 1 mm) with unevenly spaced nodes, stations picked among them."""
    rng = np.random.default_rng(seed)
    axis = np.array([0.0, 0.0, 1.0])
    e1, e2 = in_plane_basis(axis)
    angles, heights = [], []
    for h in (0.0, 1e-3):
        a = (2 * math.pi * (np.arange(band_nodes) + 0.3 * rng.random(band_nodes)) / band_nodes) % (2 * math.pi)
        angles.append(a)
        heights.append(np.full(band_nodes, h))
    angles, heights = np.concatenate(angles), np.concatenate(heights)
    stations = np.concatenate([np.arange(0, band_nodes, band_nodes // per_edge),
                               band_nodes + np.arange(0, band_nodes, band_nodes // per_edge)])
    dofs = np.arange(3 * angles.size).reshape(-1, 3)

    def level_weights(h):
        upper = np.asarray(h) / 1e-3
        return np.stack([1.0 - upper, upper], axis=-1)

    ring = {"axis": axis, "centre": np.zeros(3), "e1": e1, "e2": e2, "node_angles": angles[stations],
            "rule": "interface", "levels": 2, "band_angles": angles, "band_dofs": dofs,
            "band_level_weights": level_weights(heights)}
    return ring, dofs[stations], angles, heights, level_weights


def _pattern_matrix(patterns, interface_dofs, n_band_dofs):
    keys = interface_dofs.reshape(-1)
    P = np.zeros((n_band_dofs, keys.size))
    for col, key in enumerate(keys):
        dofs, values = patterns[int(key)]
        P[dofs, col] = values
    return P


def test_band_patterns_and_site_rows_are_one_interpolation():
    ring, interface, angles, heights, level_weights = _synthetic_ring()
    patterns = ring_band_patterns(ring, interface)
    P = _pattern_matrix(patterns, interface, 3 * angles.size)
    # sites at the band's own nodes: their rows must be the patterns' rows there
    sites = dict(ring, site_angles=angles, site_level_weights=level_weights(heights))
    rows = ring_interface_rows(sites, 0, 3, interface.size)
    assert np.abs(rows - P).max() < 1e-12
    # Lagrange: a station's pattern is its own unit displacement, zero at every other station
    station_dofs = interface.reshape(-1)
    assert np.allclose(P[station_dofs], np.eye(station_dofs.size), atol=1e-14, rtol=0)


def test_band_patterns_carry_a_rigid_translation():
    ring, interface, angles, heights, _ = _synthetic_ring()
    P = _pattern_matrix(ring_band_patterns(ring, interface), interface, 3 * angles.size)
    q = np.tile([1.0, 0.0, 0.0], interface.shape[0])        # every station moved 1 along x
    u = (P @ q).reshape(-1, 3)
    assert np.abs(u - [1.0, 0.0, 0.0]).max() < 1e-4
    frames = cylindrical_frames(angles, ring["e1"], ring["e2"], ring["axis"])
    assert frames.shape == (angles.size, 3, 3)


@pytest.fixture(scope="module")
def band_models():
    from mpi4py import MPI

    from app.case.schema import load_case
    from app.reduced.model import load_or_build

    out = {}
    for kind in ("nodes", "band"):
        case = load_case(MOTOR, COARSE + [f'reduction.interface="{kind}"'])
        out[kind] = (case, load_or_build(case, MPI.COMM_WORLD, lambda *a: None)[0])
    return out


def test_band_vertices_follow_their_stations(band_models):
    from mpi4py import MPI

    from app.contact.sites import contact_site_sets
    from app.fe.model import build_model

    case, model = band_models["band"]
    sets, _, _ = contact_site_sets(case, build_model(case, MPI.COMM_WORLD))
    ring_set = next(s for s in sets if s.ring is not None)
    ring = ring_set.ring
    patterns = ring_band_patterns(ring, ring_set.interface_dofs)
    keys = ring_set.interface_dofs.reshape(-1)
    assert keys.size == model.n_interface
    # the band's nodes that are mesh vertices (the stored vertex basis: u at 3 v + r, then the potentials)
    geometry = np.asarray(model.mesh_geometry)
    nearest = np.array([int(np.argmin(np.linalg.norm(geometry - x, axis=1))) for x in ring["band_xyz"]])
    is_vertex = np.linalg.norm(geometry[nearest] - ring["band_xyz"], axis=1) < 1e-12
    assert is_vertex.sum() >= keys.size // 3
    rows = model.vertex_basis[: 3 * geometry.shape[0]].reshape(-1, 3, model.size)[nearest[is_vertex]]
    expected = np.zeros((is_vertex.sum(), 3, keys.size))
    for col, key in enumerate(keys):
        dofs, values = patterns[int(key)]
        at = dict(zip(dofs.tolist(), values.tolist()))
        for i, band_row in enumerate(ring["band_dofs"][is_vertex]):
            expected[i, :, col] = [at.get(int(d), 0.0) for d in band_row]
    scale = np.abs(model.vertex_basis).max()
    assert np.abs(rows[:, :, : keys.size] - expected).max() < 1e-9 * max(scale, 1.0)
    # every other coordinate (electrodes' static modes, fixed-interface modes, enrichment) leaves the band at rest
    assert np.abs(rows[:, :, keys.size:]).max() < 1e-9 * scale


def test_band_constraint_raises_f14_a_little(band_models):
    _, nodes = band_models["nodes"]
    _, band = band_models["band"]
    free = nodes.resonances_Hz(38000.0, 2).mean()
    held = band.resonances_Hz(38000.0, 2).mean()
    assert 0.0 < held / free - 1 < 0.01, (free, held)
