"""Model surgery for the chain of controlled runs (app/reduced/surgery.py), on a small synthetic reduced structure
(random symmetric positive definite K, M, proportional C; two electrode inputs; sites on a cone): every reference
is an independent computation on the full matrices, so the tolerances are round-off (1e-9 relative: the solves
are of size < 30, condition numbers < 1e4).

* modal_pair: its natural frequencies are the full structure's two nearest the drive (eigen solve of the full
  free block); its static response to the inputs is the full structure's exactly (the static correction); its
  steady response at the drive projects on the pair as the full structure's does (the pair's coordinates are
  exact; the other modes' dynamic part is what it drops).
* rigid_wave: G v(t) equals the modal pair's steady site displacement Re(Y exp(i w t)) at every time, for the
  case's electrode pattern, scaled by ``scale``; no free coordinate moves a site (the wave is prescribed).
* planar_sites: every site row's meridional component is zero and its normal and circumferential ones are the
  unprojected rows'; cone_frames: orthonormal, the normal the contact law's (app/contact/law.py shape_gap).
* The case keys: a bad combination is one line naming the file and key, exit 2 (docs/cases.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CASES

from app.reduced import surgery as sg
from app.reduced.model import ReducedModel

FREQ_HZ = 1000.0
RTOL = 1e-9


def _model(seed=0, n_interface=9, n_modes=14, n_sites=6):
    """A reduced model: n_interface interface DOFs, 2 electrodes, n_modes modes; two natural modes near FREQ_HZ;
    sites on a cone of half angle 15 deg about z through the origin, their rows random."""
    rng = np.random.default_rng(seed)
    n = n_interface + 2 + n_modes
    A = rng.standard_normal((n, n))
    M = A @ A.T / n + np.eye(n)
    # stiffness with the free block's spectrum placed: two modes at 0.99 and 1.01 x FREQ_HZ, the rest spread
    B = rng.standard_normal((n, n))
    K0 = B @ B.T / n + np.eye(n)
    w = 2 * math.pi * FREQ_HZ
    F = np.r_[0:n_interface, n_interface + 2:n]
    import scipy.linalg

    values, vectors = scipy.linalg.eigh(K0[np.ix_(F, F)], M[np.ix_(F, F)])
    target = np.r_[(0.99 * w) ** 2, (1.01 * w) ** 2, (w * np.linspace(0.2, 6.0, F.size - 2)) ** 2]
    MF = M[np.ix_(F, F)]
    KFF = MF @ vectors @ np.diag(target) @ vectors.T @ MF
    K = K0 * w**2 / values.max()
    K[np.ix_(F, F)] = KFF
    K = 0.5 * (K + K.T)
    K += 10 * abs(K).max() * np.diag(np.r_[np.zeros(n_interface), np.ones(2), np.zeros(n_modes)])
    C = 1e-6 * K + 1.0 * M
    angles = np.linspace(0, 2 * math.pi, n_sites, endpoint=False)
    points = np.c_[0.01 * np.cos(angles), 0.01 * np.sin(angles), np.zeros(n_sites)]
    return ReducedModel(K=K, M=M, C=C, n_interface=n_interface, inputs=["A", "B"], n_electrodes=2,
                        mode_frequencies_Hz=np.zeros(n_modes), enrichment_frequencies_Hz=np.zeros(0),
                        charge_rows=rng.standard_normal((2, n)), translation_loads=rng.standard_normal((3, n)),
                        sample_names=["p"], sample_rows=rng.standard_normal((1, n)), site_points=points,
                        site_weight=np.ones(n_sites), site_contact=np.zeros(n_sites, np.int64),
                        site_rows=rng.standard_normal((3 * n_sites, n)), gdim=3, band_area_m2=np.ones(1),
                        vertex_basis=np.zeros((0, n)), mesh_geometry=np.zeros((0, 3)),
                        mesh_topology=np.zeros((0, 4), np.int64), mesh_region=np.zeros(0, np.int64),
                        mesh_topology_type="tetrahedron", derived_basis=np.zeros((0, n)), region_table=[],
                        reduction_wall_s=0.0, fe_dofs=0, mass_kg=1.0)


def _static_sites(model, v):
    P = np.arange(model.n_interface, model.n_interface + len(model.inputs))
    F = np.setdiff1d(np.arange(model.size), P)
    x = np.zeros(model.size)
    x[P] = v
    x[F] = -np.linalg.solve(model.K[np.ix_(F, F)], model.K[np.ix_(F, P)] @ v)
    return model.site_rows @ x


def test_modal_pair_keeps_the_pair_and_the_static_response():
    model = _model()
    pair = sg.modal_pair(model, FREQ_HZ)
    assert pair.size == 4 and pair.n_interface == 0
    np.testing.assert_allclose(pair.resonances_Hz(FREQ_HZ), model.resonances_Hz(FREQ_HZ), rtol=RTOL)
    np.testing.assert_allclose(pair.resonances_Hz(FREQ_HZ), [0.99 * FREQ_HZ, 1.01 * FREQ_HZ], rtol=1e-8)
    v = np.array([0.7, -1.3])
    expected = _static_sites(model, v)
    np.testing.assert_allclose(_static_sites(pair, v), expected, rtol=0, atol=RTOL * abs(expected).max())
    # the pair's own amplitude in the steady response: the full structure's modal projection, exactly
    phi, _ = sg.pair_modes(model, FREQ_HZ)
    omega = 2 * math.pi * FREQ_HZ
    P, F = np.r_[9:11], np.r_[0:9, 11:model.size]
    D = model.K - omega**2 * model.M + 1j * omega * model.C
    xF = np.linalg.solve(D[np.ix_(F, F)], -D[np.ix_(F, P)] @ v)
    Dp = pair.K - omega**2 * pair.M + 1j * omega * pair.C
    eta = np.linalg.solve(Dp[2:, 2:], -Dp[2:, :2] @ v)
    # full: the pair's modal amplitudes of x_F (M-orthogonal projection); pair model: eta plus the static part's
    # projection
    psi = -np.linalg.solve(model.K[np.ix_(F, F)], model.K[np.ix_(F, P)])
    full = phi.T @ model.M[np.ix_(F, F)] @ xF
    mine = eta + phi.T @ model.M[np.ix_(F, F)] @ psi @ v
    # not exact: C couples the modes (C is not diagonal in Phi here); with damping 1e-6 K + M the coupling is
    # O(zeta) ~ 1e-3 of the resonant amplitude
    np.testing.assert_allclose(mine, full, rtol=5e-3)


def test_rigid_wave_prescribes_the_pairs_free_wave():
    model = sg.modal_pair(_model(), FREQ_HZ)
    amplitudes, phases = np.array([1.0, 0.8]), np.radians([0.0, 90.0])
    Y = sg.harmonic_site_phasor(model, FREQ_HZ, amplitudes * np.exp(1j * phases))
    for scale in (1.0, 0.37):
        rigid = sg.rigid_wave(model, FREQ_HZ, amplitudes, phases, scale)
        assert not rigid.site_rows[:, 2:].any()                 # the modes: no site moves with them
        omega = 2 * math.pi * FREQ_HZ
        for t in np.linspace(0, 1 / FREQ_HZ, 7):
            v = 3.0 * amplitudes * np.cos(omega * t + phases)    # any voltage
            expected = 3.0 * scale * (Y * np.exp(1j * omega * t)).real
            np.testing.assert_allclose(rigid.site_rows[:, :2] @ v, expected, rtol=0,
                                       atol=RTOL * abs(Y).max() * 3)
    with pytest.raises(ValueError, match="two independent phases"):
        sg.rigid_wave(model, FREQ_HZ, amplitudes, np.radians([0.0, 180.0]))


def test_planar_sites_drop_the_meridional_motion():
    from app.contact.law import shape_gap

    model = _model()
    frames = sg.cone_frames(model.site_points, [0, 0, 0.0], [0, 0, 1.0], math.radians(15.0))
    for frame in frames:
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-14)
    # the normal is the contact law's (a cone of half angle 15 deg about z, radius 0.01 at the reference)
    n, Dn = np.zeros(3), np.zeros((3, 3))
    shape_gap(2, np.array([0, 0, 1.0]), 0.01, math.radians(15.0), model.site_points[1], n, Dn)
    np.testing.assert_allclose(frames[1, 0], n, atol=1e-14)
    planar = sg.planar_sites(model, np.arange(6), frames)
    for i, frame in enumerate(frames):
        before, after = frame @ model.site_rows[3 * i:3 * i + 3], frame @ planar.site_rows[3 * i:3 * i + 3]
        np.testing.assert_allclose(after[:2], before[:2], rtol=0, atol=1e-14 * abs(before).max())
        assert abs(after[2]).max() < 1e-14 * abs(before).max()
        assert abs(before[2]).max() > 0.1         # the rows did have a meridional part


def test_travelling_component_is_the_travelling_wave():
    """A wave of order 4 travelling backwards (sign -1: exp(-i 4 angle)), plus a standing part of order 4 (which
    adds to both directions, here 0.1 of the amplitude) and an order-3 ripple, sampled at 64 evenly spaced sites:
    the travelling component is the backward order-4 wave plus the standing part's backward half, exactly (discrete
    Fourier orthogonality: round-off)."""
    n_sites = 64
    angles = np.linspace(0, 2 * math.pi, n_sites, endpoint=False) + 0.3
    frames = sg.cone_frames(np.c_[np.cos(angles), np.sin(angles), np.zeros(n_sites)], [0, 0, 0], [0, 0, 1.0],
                            math.radians(15.0))
    amplitude = np.array([2.0 + 1.0j, 0.5 - 0.7j, 0.2j])            # normal, circumferential, meridional phasors
    back = np.exp(-4j * angles)
    local = amplitude[None, :] * back[:, None] + 0.1 * np.cos(4 * angles)[:, None] * amplitude[None, :] \
        + 0.3 * np.exp(3j * angles)[:, None]
    Y = np.einsum("nkj,nk->nj", frames, local).reshape(-1)        # frames are orthonormal: local -> global
    out, order, sign = sg.travelling_component(Y, np.arange(n_sites), frames, sg.cone_angles(
        np.c_[np.cos(angles), np.sin(angles), np.zeros(n_sites)], [0, 0, 0], [0, 0, 1.0]))
    assert (order, sign) == (4, 1)                # exp(+i 4 angle) x the wave's exp(-i 4 angle) is the mean taken
    expected = np.einsum("nkj,nk->nj", frames, (1.05 * amplitude)[None, :] * back[:, None]).reshape(-1)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-13)


MOTOR = CASES / "wwusm-motor.toml"


@pytest.mark.parametrize("sets, key", [
    (['reduction.surgery="rigid"'], "reduction.surgery"),
    (["reduction.wave_scale=0.5"], "reduction.wave_scale"),                     # without a rigid wave
    (['reduction.surgery="rigid_wave"', "reduction.wave_scale=-1"], "reduction.wave_scale"),
    (['reduction.surgery="rigid_wave"', "electrodes.B.phase_deg=180.0", "electrodes.Bm.phase_deg=0.0"],
     "reduction.surgery"),                                                       # a standing drive
    (['tier="fe"', 'reduction.site_motion="planar"'], "reduction.site_motion"),
    (['reduction.surgery="travelling_wave"', 'transient.contacts[0].shape="plane"',
      "transient.contacts[0].normal=[0.0, 0.0, 1.0]"], "reduction.surgery"),      # no cone to go round
    (['reduction.site_motion="planar"', 'transient.contacts[0].shape="plane"',
      "transient.contacts[0].normal=[0.0, 0.0, 1.0]"], "transient.contacts[0].shape"),
])
def test_bad_surgery_keys_name_file_and_key(cli, sets, key):
    args = [a for s in sets for a in ("--set", s)]
    result = cli("validate", MOTOR, *args)
    assert result.returncode == 2, result.stderr + result.stdout
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert MOTOR.name in lines[0] and key in lines[0], lines[0]


def test_surgery_keys_share_the_cached_model():
    """The surgery acts on the built model (docs/cases.md): every step of a chain reads one cached reduced model, so
    the keys are not in its cache key (app/reduced/model.py cache_key), while a basis key is."""
    from app.case.schema import load_case
    from app.reduced.model import cache_key

    plain = cache_key(load_case(MOTOR))
    chain = cache_key(load_case(MOTOR, ['reduction.surgery="rigid_wave"', 'reduction.site_motion="planar"',
                                        "reduction.wave_scale=0.8"]))
    assert chain == plain
    assert cache_key(load_case(MOTOR, ["reduction.interface_nodes=32"])) != plain
