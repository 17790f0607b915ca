"""Rings of contact sites across the band's height (``transient.contacts[].sample_rings``, app/contact/sites.py).

References and tolerances:
- ``ring_heights``: Gauss-Legendre in height, so the weights sum to 1 and integrate a polynomial of degree
  2 n - 1 over the band exactly (round-off, 1e-14); the ring nearest the middle comes first (the contact's probe);
- the sites of ``ring_sites`` lie on the cone at their height, r(h) = r_c + h tan(alpha) (round-off); their areas
  sum to the band's (round-off) and grow with the ring's radius; one ring is the contact circle, exactly the
  single-ring sampling;
- with the band interface the sites' rows interpolate linearly in height between the band's edges: a pure tilt
  (the upper stations moved, the lower ones not) moves a site by its height fraction, to round-off (1e-12);
- a modal run with two rings writes the contact in the wave's frame per ring (``motor_wave_frame.csv``), its normal
  force conserved (:func:`_check_wave_frame`).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from app.contact.sites import in_plane_basis, ring_heights, ring_interface_rows, ring_sites

RADIUS, HALF_ANGLE, H_LO, H_HI = 12.86e-3, 15.0, -1.5e-4, 1.5e-4


def test_ring_heights_are_gauss_legendre_across_the_band():
    for n in (1, 2, 3, 4, 5):
        h, w = ring_heights(n, H_LO, H_HI)
        assert abs(w.sum() - 1.0) < 1e-14
        assert np.all((h > H_LO) & (h < H_HI))
        # exact for degree 2n - 1: the mean of h^k over the band
        for k in range(2 * n):
            exact = (H_HI ** (k + 1) - H_LO ** (k + 1)) / ((k + 1) * (H_HI - H_LO))
            assert abs(w @ h ** k - exact) <= 1e-13 * max(abs(H_LO), abs(H_HI)) ** k
        mid = 0.5 * (H_LO + H_HI)
        assert abs(h[0] - mid) == np.abs(h - mid).min()


def _cone_band(n_round=96):
    """A band of nodes on the cone (two edges), as app/reduced/surface.py's SurfaceNodes gives it."""
    axis = np.array([0.0, 0.0, 1.0])
    e1, e2 = in_plane_basis(axis)
    angles = 2 * math.pi * np.arange(n_round) / n_round
    xyz, area = [], []
    for h in (H_LO, H_HI):
        r = RADIUS + h * math.tan(math.radians(HALF_ANGLE))
        xyz.append(h * axis + r * (np.outer(np.cos(angles), e1) + np.outer(np.sin(angles), e2)))
        area.append(np.full(n_round, 1.0))
    xyz = np.concatenate(xyz)
    nodes = SimpleNamespace(size=xyz.shape[0], coordinates_m=xyz, area_m2=np.concatenate(area) * 1e-8,
                            global_dofs=np.arange(xyz.size).reshape(-1, 3))
    section = SimpleNamespace(shape="cone", axis=list(axis), radius_m=RADIUS, half_angle_deg=HALF_ANGLE,
                              name="stator_rotor")
    case = SimpleNamespace(source="case.toml")
    body = SimpleNamespace(position_m=[0.0, 0.0, 0.0], rotations=[])
    return nodes, section, case, body


def _sites(n_rings, band=True, points=64, stations=16):
    nodes, section, case, body = _cone_band()
    area = float(nodes.area_m2.sum())
    return ring_sites(0, section, case, body, nodes, area, points, stations, "interface", "transient.contacts[0]",
                      band=band, n_rings=n_rings), area


def test_ring_sites_lie_on_the_cone_and_share_the_band_area():
    one, area = _sites(1)
    assert np.allclose(one.points_m[:, 2], 0.0, atol=0) and np.allclose(np.hypot(*one.points_m[:, :2].T), RADIUS,
                                                                         rtol=1e-15, atol=0)
    assert abs(one.weight.sum() - area) < 1e-15 * area
    for n in (2, 3, 4):
        sites, _ = _sites(n)
        h = sites.points_m[:, 2]
        r = np.hypot(sites.points_m[:, 0], sites.points_m[:, 1])
        assert np.abs(r - (RADIUS + h * math.tan(math.radians(HALF_ANGLE)))).max() < 1e-15
        assert abs(sites.weight.sum() - area) < 1e-14 * area
        expected_h, w = ring_heights(n, H_LO, H_HI)
        assert np.allclose(h.reshape(n, -1), expected_h[:, None], rtol=0, atol=1e-18)
        per_ring = sites.weight.reshape(n, -1).sum(axis=1)
        ring_r = RADIUS + expected_h * math.tan(math.radians(HALF_ANGLE))
        assert np.allclose(per_ring / area, w * ring_r / (w @ ring_r), rtol=1e-13, atol=0)
        # every ring has the same angles, the ring-major layout the scene's ring table folds
        angles = np.arctan2(sites.points_m[:, 1], sites.points_m[:, 0]).reshape(n, -1)
        assert np.allclose(angles, angles[0], rtol=0, atol=1e-12)


def test_band_rows_follow_the_tilt_across_the_rings():
    sites, _ = _sites(3)
    ring = sites.ring
    k = sites.interface_dofs.shape[0]
    rows = ring_interface_rows(ring, 0, 3, 3 * k).reshape(-1, 3, 3 * k)
    # a tilt: every upper station moved 1 along its own radius, the lower ones not
    q = np.zeros((k, 3))
    angles = ring["node_angles"]
    upper = np.arange(k) >= k // 2
    q[upper, 0], q[upper, 1] = np.cos(angles[upper]), np.sin(angles[upper])
    u = rows @ q.reshape(-1)
    h = sites.points_m[:, 2]
    fraction = (h - H_LO) / (H_HI - H_LO)
    site_angles = ring["site_angles"]
    radial = u[:, 0] * np.cos(site_angles) + u[:, 1] * np.sin(site_angles)
    # a uniform radial motion of the upper edge: cubic interpolation of a constant is exact
    assert np.abs(radial - fraction).max() < 1e-12
    assert np.abs(u[:, 2]).max() < 1e-12


def test_a_modal_run_with_two_rings_reports_one_ring_table(tmp_path):
    """The tests' coarse stator with the band interface and two rings: the sites' table holds both rings (two
    heights, the band's area), and the scene's ring table folds them into one row per angle, the area-weighted mean
    of the two rings' pressures (round-off)."""
    import csv

    import h5py
    from conftest import CASES

    from app.runner import run_case

    coarse = ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
              "reduction.interface_nodes=32", "transient.contacts[0].sample_points=128",
              'reduction.interface="band"', "transient.contacts[0].sample_rings=2", "transient.end_time_s=0.0005",
              "output.plots=false", "output.fields=false"]
    results = run_case(CASES / "wwusm-motor.toml", coarse, tmp_path / "rings", quiet=True)["results"]["transient"]
    assert results["cutbacks"] == 0
    with h5py.File(tmp_path / "rings" / results["time_series"], "r") as f:
        geometry = f["stator_rotor_sites_geometry"][()]
        pressure = f["stator_rotor_sites_pressure"][()]
    assert geometry.shape == (256, 4)
    heights = np.unique(np.round(geometry[:, 2], 12))
    assert heights.size == 2
    with open(tmp_path / "rings" / "motor_ring.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 128
    area = geometry[:, 3].reshape(2, 128)
    last = pressure[-1].reshape(2, 128)
    folded = (last * area).sum(axis=0) / area.sum(axis=0)
    angle = np.degrees(np.arctan2(geometry[:128, 1], geometry[:128, 0])) % 360.0
    order = np.argsort(angle)
    written = np.array([float(r["last_period_pressure_Pa"]) for r in rows])
    assert np.allclose(written, folded[order], rtol=1e-6, atol=1e-6 * max(np.abs(folded).max(), 1.0))
    assert last.max() > 0.0       # the rotor is seated: some site carries pressure
    _check_wave_frame(tmp_path / "rings", results)


def _check_wave_frame(out, results):
    """The contact in the wave's frame (``motor_wave_frame.csv``, app/contact/tables.py) of the two-ring run: both
    rings, 36 bins of wave phase each; its normal force per bin sums to the mean of the sites' pressure x area over
    the same rows and to the time series' normal force over the same steps (the same products summed: the CSV's 8
    digits, 1e-7); contact = stick + forward + backward slip in every bin (8 digits); the contact centre of the
    summary (from the sites' first harmonics) within half a bin (5 deg) of the bins' pressure-weighted mean phase,
    and near the crest (within 45 deg of wave: the rotor rests on the crests, where the stator comes closest);
    the slip speed's parts while slipping bound the slip speed, max(e1, e2) <= |s| <= e1 + e2 (round-off); the
    friction power's parts sum to the contact's friction loss (below)."""
    import csv

    import h5py

    from app.contact.tables import wave_frame_centre_rad

    with h5py.File(out / results["time_series"], "r") as f:
        series = {k: f[k][()] for k in f}
    with open(out / "motor_wave_frame.csv") as fh:
        frame = {k: np.array([float(r[k]) for r in rows]) for rows in [list(csv.DictReader(fh))] for k in rows[0]}
    assert frame["ring"].size == 72 and set(frame["ring"]) == {0.0, 1.0}
    assert np.unique(frame["ring_height_m"]).size == 2
    times = series["stator_rotor_sites_time"]
    bins = series["stator_rotor_sites_wave_frame"]
    populated = bins[..., 0].reshape(len(bins), -1).sum(axis=1) > 0
    assert not populated[0] and populated[1:].all()       # the first interval has no wave phase yet
    motor = results["statistics"]["motor"]
    t = series["time_s"]
    assert t[-1] - motor["window_s"] <= times[1, 0] * (1 + 1e-9)    # the window spans every populated row
    total = frame["normal_force_N"].sum()
    area = series["stator_rotor_sites_geometry"][:, 3]
    from_sites = (series["stator_rotor_sites_pressure"][1:] @ area).mean()
    assert total == pytest.approx(from_sites, rel=1e-7)
    steps = (t > times[1, 0] * (1 + 1e-12)) & (t <= times[-1, 1] * (1 + 1e-12))
    from_series = (series["stator_rotor_normal_force_N"][steps] * series["dt_s"][steps]).sum() / (
        times[-1, 1] - times[1, 0])
    assert total == pytest.approx(from_series, rel=1e-7)
    assert total > 0.1 * motor["normal_force_N"]
    parts = frame["stick_fraction"] + frame["forward_slip_fraction"] + frame["backward_slip_fraction"]
    assert np.allclose(frame["contact_fraction"], parts, rtol=1e-7, atol=1e-8)
    centre = math.degrees(wave_frame_centre_rad(bins[1:].sum(axis=0)))
    assert abs(motor["contact_centre_from_crest_deg"] - centre) < 5.0
    assert abs(centre) < 45.0        # the rotor rests on the crests (not 180 deg away, in a trough)
    e1, e2, s = (motor[f"slip_speed{k}_m_per_s"] for k in ("_circumferential", "_meridional", ""))
    assert max(e1, e2) <= s * (1 + 1e-12) and s <= (e1 + e2) * (1 + 1e-12) and s > 0
    assert 0.0 <= motor["meridional_slip_power_share"] <= 1.0
    # the friction power's two parts add up to the contact's loss less its penalty damping: the kernel's own
    # dissipation, from the same step powers (trapezoidal in time there, per step here); measured 0.979 of it on
    # this impacting run (0.9996 on the coarse free rotor of tests/test_motor_modal.py)
    split = motor["friction_power_circumferential_W"] + motor["friction_power_meridional_W"]
    assert 0.9 * motor["friction_loss_W"] <= split <= 1.01 * motor["friction_loss_W"]
