"""The motor in the modal tier (app/reduced/motor.py, app/reduced/ring_kernel.py).

* The Newton matrix of the condensed step (contact + regularised Coulomb friction on the cone, rotor axial
  and spin equations) equals the finite-difference derivative of the residual, in stick, slip and
  mixed states: the kernel's quadratic convergence rests on it.
* On a coarse stator (cached reduced model), the motor's closed-form bounds: a held rotor's mean friction
  torque lies below the Coulomb bound mu_s N r_c, the mean normal force is the preload over sin(15 deg)
  (axial balance of a sliding cone), the discrete energy identity of the average-acceleration scheme
  closes, and a free rotor turns the way the wave drives it.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.reduced import ring_kernel as rk

ALPHA = math.radians(15.0)


def _synthetic_ring(n_b: int, rng):
    angles = 2 * math.pi * np.arange(n_b) / n_b
    rho = np.full(n_b, 0.0128)
    frame = np.zeros((n_b, 3, 3))
    for i, th in enumerate(angles):
        e_r = np.array([math.cos(th), math.sin(th), 0.0])
        e_t = np.array([-math.sin(th), math.cos(th), 0.0])
        e_z = np.array([0.0, 0.0, 1.0])
        frame[i] = [math.cos(ALPHA) * e_r - math.sin(ALPHA) * e_z, e_t, math.sin(ALPHA) * e_r + math.cos(ALPHA) * e_z]
    A = rng.normal(size=(3 * n_b, 3 * n_b))
    G = 1e-8 * (A @ A.T / (3 * n_b) + np.eye(3 * n_b))      # SPD compliance [m/N]
    return rho, frame, G


@pytest.mark.parametrize("sampling", ["nodal", "interpolated"])
@pytest.mark.parametrize("slip_scale", [1e-5, 1e-4, 3e-2])     # stick, transition, slip (eps = 1e-4 m/s)
def test_newton_matrix_matches_finite_differences(slip_scale, sampling):
    from app.reduced.motor import _cone_frames, interpolation_stencil

    rng = np.random.default_rng(7)
    n_b = 6
    rho, frame, G = _synthetic_ring(n_b, rng)
    nB = 3 * n_b
    if sampling == "nodal":
        idx, B = np.arange(n_b).reshape(-1, 1), np.tile(np.eye(3), (n_b, 1, 1, 1))
        n_c = n_b
    else:
        # 15 points between the 6 nodes, each interpolated (cubic) from 4 of them in the local frames
        n_c = 15
        node_angles = 2 * math.pi * np.arange(n_b) / n_b
        angles = 2 * math.pi * (np.arange(n_c) + 0.3) / n_c
        idx, weights = interpolation_stencil(node_angles, angles)
        point_frame = _cone_frames(angles, math.sin(ALPHA), math.cos(ALPHA))
        B = weights[:, :, None, None] * np.einsum("cki,cskj->csij", point_frame, frame[idx])
        frame, rho = point_frame, np.full(n_c, rho[0])
    dt, beta, gamma = 6.93e-7, 0.25, 0.5
    c_a, cv = 1 / (beta * dt * dt), gamma / (beta * dt)
    g0 = np.zeros(n_c)
    area = np.full(n_c, 4e-7 * n_b / n_c)
    k, mu_d, fact, decay, tau_cap, eps = 4e13, 0.57, 1.298, 50.0, 124.13e6, 1e-4
    mass, preload, inertia, load, brake = 0.018, 0.98, 1.5e-6, -0.004, 1e-4
    # half the nodes 20-40 nm inside the cone, half 10 nm outside; velocities give the chosen slip speeds
    node_frame = _synthetic_ring(n_b, np.random.default_rng(7))[1]
    normal_offset = np.where(np.arange(n_b) % 2 == 0, -3e-8, 1e-8)
    uB = np.concatenate([normal_offset[i] * node_frame[i, 0] for i in range(n_b)])
    xtB = uB - rng.normal(size=nB) * slip_scale / cv
    vtB = rng.normal(size=nB) * slip_scale
    w = np.zeros(nB + 4)
    w[:nB] = uB + 1e-9 * rng.normal(size=nB)
    dz_t, dzr_t, spin_t = 2e-9, 1e-4, 3.0

    def residual(u, dd, ds, jac):
        arrays = (np.zeros(nB), np.zeros((n_c, 3)), np.zeros((n_c, 3, 3)), np.zeros((n_c, 3)), np.zeros((n_c, 3)),
                  np.zeros(n_c), np.zeros((n_c, 2)), np.zeros((n_c, 3)), np.zeros((n_c, 3)), np.zeros(nB),
                  np.zeros(nB))
        Rz, Rs, _, _ = rk._residual(u, dd, ds, w, G, xtB, vtB, cv, c_a, dz_t, dzr_t, spin_t, dt, gamma, frame, g0,
                                    rho, area, idx, B, math.sin(ALPHA), math.cos(ALPHA), k, mu_d, fact, decay,
                                    tau_cap, eps, mass, preload, inertia, load, brake, True, *arrays, jac)
        return arrays, Rz, Rs

    dd0, ds0 = 1e-10, 1e-3
    (fB, _, D, dfdz, dfds, fn, s, _, _, vB, Ru), Rz, Rs = residual(uB, dd0, ds0, True)
    assert 0 < np.count_nonzero(fn) < n_c
    J, R, active, na, *_ = rk._newton_system(Ru, Rz, Rs, G, D, dfdz, dfds, fn, frame, rho, idx, B, n_b, mass, c_a,
                                             inertia, gamma, dt, brake, True)
    m = 3 * na + 2

    def vector(u, dd, ds):
        (*_, Ru_), Rz_, Rs_ = residual(u, dd, ds, False)
        out = np.empty(m)
        for ia in range(na):
            out[3 * ia:3 * ia + 3] = Ru_[3 * active[ia]:3 * active[ia] + 3]
        out[m - 2], out[m - 1] = Rz_, Rs_
        return out

    assert np.allclose(vector(uB, dd0, ds0), R)
    fd = np.empty((m, m))
    for col in range(m):
        if col < m - 2:
            h = 1e-16
            i = 3 * active[col // 3] + col % 3
            up, dn = uB.copy(), uB.copy()
            up[i] += h
            dn[i] -= h
            fd[:, col] = (vector(up, dd0, ds0) - vector(dn, dd0, ds0)) / (2 * h)
        elif col == m - 2:
            h = 1e-16
            fd[:, col] = (vector(uB, dd0 + h, ds0) - vector(uB, dd0 - h, ds0)) / (2 * h)
        else:
            h = 1e-9
            fd[:, col] = (vector(uB, dd0, ds0 + h) - vector(uB, dd0, ds0 - h)) / (2 * h)
    # central differences with steps ~1e-8 of the unknowns carry ~1e-5 of a column in round-off; a wrong
    # derivative term is off by O(1)
    column_scale = np.abs(fd).max(axis=0)
    assert np.max(np.abs(J - fd) / column_scale) < 2e-4


# 128 contact points on the coarse stator's 32 ring nodes: within 2 % of 512 (test_contact_sampling_converges)
COARSE = ["geometry.parameters.mesh_size_m=0.003", "geometry.parameters.tip_mesh_size_m=0.001",
          "reduction.ring_points=32", "reduction.contact_points=128", "transient.end_time_s=0.008"]


@pytest.fixture(scope="module")
def motor_runs(tmp_path_factory):
    """A held and a free rotor on a coarse stator (one reduced model, built once into a private cache)."""
    import os

    from app.runner import run_case

    root = tmp_path_factory.mktemp("motor")
    old = os.environ.get("PIEZODYN_CACHE_DIR")
    os.environ["PIEZODYN_CACHE_DIR"] = str(root / "cache")
    try:
        held = run_case("cases/wwusm-motor.toml", COARSE + ['transient.bodies[0].rotations[0].motion="fixed"'],
                        root / "held", quiet=True)
        free = run_case("cases/wwusm-motor.toml", COARSE, root / "free", quiet=True)
        # the hard cases, which must finish without abort: no preload (the rotor is thrown off the
        # crests) and a 10x penalty
        short = COARSE + ["transient.end_time_s=0.003", "output.plots=false"]
        hard = {name: run_case("cases/wwusm-motor.toml", short + sets, root / name, quiet=True)["results"]["transient"]
                for name, sets in (("no_preload", ["transient.bodies[0].applied_force_N=[0.0, 0.0, 0.0]"]),
                                   ("penalty_10x", ["transient.contacts[0].stiffness=4e14"]),
                                   ("prescribed_spin", ['transient.bodies[0].rotations[0].motion="constant_rate"',
                                                        "transient.bodies[0].rotations[0].rate_rad_per_s=1.2"]))}
    finally:
        if old is None:
            os.environ.pop("PIEZODYN_CACHE_DIR")
        else:
            os.environ["PIEZODYN_CACHE_DIR"] = old
    return root, held["results"]["transient"], free["results"]["transient"], hard


def test_held_rotor_bounds_and_energy(motor_runs):
    _, held, _, _ = motor_runs
    m = held["motor"]
    assert held["cutbacks"] == 0
    # the stall torque of a sliding contact stays below the Coulomb bound mu_s N r_c (DESIGN.md 6)
    assert 0.3 * m["coulomb_torque_bound_N_m"] < m["friction_torque_N_m"] < m["coulomb_torque_bound_N_m"]
    # axial balance of a cone sliding round the ring: N sin(15 deg) + f_m cos(15 deg) = P, the meridional friction
    # f_m (from the rotor's axial bounce) carrying a few % of P: 3 % here with 128 contact points, 1 % node-sampled
    assert m["normal_force_N"] == pytest.approx(m["normal_force_closed_form_N"], rel=0.05)
    # the average-acceleration scheme's discrete energy identity with the electrode reactions closes to round-off;
    # with the FE tier's charge functional the gap is the coarse basis's charge error (0.14 % on the case mesh)
    assert abs(m["energy_balance_reactions_relative"]) < 1e-6
    assert abs(m["energy_balance_relative"]) < 0.05
    # after 288 periods the coarse stator's wave is still ringing down from its free amplitude: the electrical
    # input plus the stored energy it releases is what friction and damping dissipate
    released_W = -m["stored_energy_change_J"] / m["window_s"]
    assert m["electrical_power_W"] + released_W == pytest.approx(m["friction_loss_W"] + m["damping_loss_W"], rel=0.05)
    fractions = m["fractions"]
    assert sum(fractions.values()) == pytest.approx(1.0)
    assert fractions["stick"] < 0.1                   # a held rotor: the contact slides


def test_reduced_stator_resonance_is_the_fe_one(motor_runs, tmp_path):
    """With the FE stator's F(1,4) pair in the basis (reduction.enrich_modes = 2), the reduced stator's resonances
    nearest the drive are the FE modal analysis's short-circuit ones (Rayleigh-Ritz is exact on its span): to the
    eigensolver's tolerance, against +0.39 % for this 32-node basis without them (docs/motor-rotor.md). The drive
    sits within two damping bandwidths of F(1,4), so that detuning halved the wave."""
    from app.runner import run_case

    _, held, _, _ = motor_runs
    fe = run_case("cases/wwusm-motor.toml",
                  COARSE[:2] + ['tier="fe"', 'analyses=["modal"]', "modal.target_frequency_Hz=36065.0",
                                "modal.n_modes=2", "output.fields=false", "output.plots=false"],
                  tmp_path / "fe_modal", quiet=True)["results"]["modal"]
    fe_Hz = sorted(mode["resonance_Hz"] for mode in fe["modes"])
    reduction = held["reduction"]
    assert reduction["enrichment_modes_Hz"] == pytest.approx(fe_Hz, rel=1e-9)
    assert reduction["stator_resonances_near_drive_Hz"] == pytest.approx(fe_Hz, rel=1e-9)


def test_free_rotor_turns_with_the_wave(motor_runs):
    root, held, free, _ = motor_runs
    m = free["motor"]
    assert free["cutbacks"] == 0
    # the rotor turns the way the contact nodes' mean tangential speed drives it, below the surface speed
    assert np.sign(m["speed_rad_per_s"]) == np.sign(m["drive_speed_m_per_s"]) != 0
    assert abs(m["speed_rad_per_s"]) * m["contact_radius_m"] < abs(m["drive_speed_m_per_s"]) * 1.5
    assert abs(m["friction_torque_N_m"]) < held["motor"]["friction_torque_N_m"]
    for name in ("motor_ring.csv", "motor_contact_path.csv", "motor_ring_pressure.png", "motor_contact_path.png"):
        assert (root / "free" / name).is_file()
    summary = json.loads((root / "free" / "summary.json").read_text())
    assert summary["results"]["transient"]["motor"]["speed_rpm"] == pytest.approx(m["speed_rpm"])
    # the FE tier's contact-area series, by the same name: the band area of the closed contact points
    import h5py

    with h5py.File(root / "free" / "transient.h5", "r") as f:
        area = f["stator_rotor_area_in_contact_m2"][()]
        points = f["stator_rotor_points_in_contact"][()]
    band = free["reduction"]["band_area_m2"]
    assert 0 < area.max() <= band
    assert area == pytest.approx(points * band / free["reduction"]["contact_points"], rel=1e-12)


def test_hard_cases_finish(motor_runs):
    *_, hard = motor_runs
    for name, run in hard.items():
        # it ran to the end, or stopped at a steady state (a rotor thrown clear coasts at a constant speed)
        assert run["steady"] or run["simulated_time_s"] == pytest.approx(0.003, rel=0.02), name
        assert run["cutbacks"] <= run["steps"] // 100, name
    # without preload the first crest throws the rotor off: it flies clear of the ring
    assert hard["no_preload"]["motor"]["fractions"]["separation"] > 0.9


def test_prescribed_spin_energy_identity(motor_runs):
    """A spin prescribed at a constant rate: the constraint takes the contact torque's work as the output, so
    the scheme's discrete energy identity with the electrode reactions closes to round-off (as for the held and
    free rotors), and the output power is the friction torque times the speed."""
    *_, hard = motor_runs
    m = hard["prescribed_spin"]["motor"]
    assert m["speed_rad_per_s"] == pytest.approx(1.2, rel=1e-12)
    assert abs(m["energy_balance_reactions_relative"]) < 1e-6
    assert m["output_power_W"] == pytest.approx(m["friction_torque_N_m"] * 1.2, rel=1e-9)


def test_contact_sampling_converges(motor_runs):
    """The contact points' sampling (reduction.contact_points, interpolated from the ring nodes) is converged: on
    the coarse stator, continuing the free rotor's run for 60 periods with 256 and with 512 contact points gives the
    same mean speed within 2 % (measured: 72.03 and 72.29 rpm; 1024 points 72.27), while the node-sampled contact
    (the 32 ring nodes themselves, unevenly spaced and each carrying band area / 32) is off by more than 10 %
    (measured: 54.65 rpm, -24 %). A held rotor discriminates less on this basis (node-sampled torque +1.8 %, 512
    against 1024 points 0.005 %). docs/motor-rotor.md, "Contact sampling"."""
    import os

    from app.reduced import motor

    root, *_ = motor_runs
    old = os.environ.get("PIEZODYN_CACHE_DIR")
    os.environ["PIEZODYN_CACHE_DIR"] = str(root / "cache")
    periods = 60
    speed = {}
    try:
        for points in (0, 256, 512):
            sets = COARSE + [f"reduction.contact_points={points}",
                             f"transient.end_time_s={periods * 2.7728e-5!r}", "output.plots=false",
                             f"transient.steady_state.window_cycles={periods - 20}",
                             "transient.steady_state.relative_tolerance=1e-9"]
            result = motor.run_continued("cases/wwusm-motor.toml", sets, root / f"sampling_{points}",
                                         root / "free" / "motor_state.npz")
            assert result["periods"] == periods and result["cutbacks"] == 0
            speed[points] = result["motor"]["speed_rad_per_s"]
    finally:
        if old is None:
            os.environ.pop("PIEZODYN_CACHE_DIR")
        else:
            os.environ["PIEZODYN_CACHE_DIR"] = old
    assert speed[256] == pytest.approx(speed[512], rel=0.02)
    assert abs(speed[0] - speed[512]) > 0.10 * abs(speed[512])



def test_motor_depends_on_preload_per_volt(motor_runs):
    """The rigid-rotor motor is positively homogeneous of degree one: the stator and the penalty are linear, Coulomb
    friction is proportional to the normal force (DC = 0, the shear cap far away) and the rotor's mass and inertia
    are linear, so the preload and the drive voltage scaled by s (with the friction regularisation speed) scale every
    displacement, speed and force by s and every power by s^2; only the penalty's 1 nm rounding keeps a scale. So
    the motor depends on the preload per volt: the paper's 4.116 N at 4.2 x 200 V runs as 0.98 N at 200 V, while
    4.116 N at 200 V collapses onto the whole ring (docs/motor-rotor.md, "Why 4.116 N collapses"; measured on this
    stator, 200 periods: speed, normal force, rotor height and electrical power in the ratios s, s, s, s^2 to 2e-5,
    2e-5, 1.5e-4, 1e-4; separation 0.92 against 0.06 at the unscaled voltage)."""
    import os

    from app.reduced import motor

    root, *_ = motor_runs
    old = os.environ.get("PIEZODYN_CACHE_DIR")
    os.environ["PIEZODYN_CACHE_DIR"] = str(root / "cache")
    periods = 200
    scale = 4.116 / 0.98
    runs = {}
    try:
        for name, s_preload, s_volt in (("base", 1.0, 1.0), ("scaled", scale, scale), ("preload_only", scale, 1.0)):
            sets = COARSE + [f"transient.end_time_s={periods * 2.7728e-5!r}", "output.plots=false",
                             "transient.steady_state.relative_tolerance=1e-9",
                             f"transient.bodies[0].applied_force_N=[0.0, 0.0, {-0.98 * s_preload!r}]",
                             f"electrodes.A.amplitude_V={200.0 * s_volt!r}",
                             f"electrodes.B.amplitude_V={200.0 * s_volt!r}",
                             f"transient.contacts[0].friction.regularisation_speed_m_per_s={1e-4 * s_volt!r}"]
            runs[name] = motor.run_continued("cases/wwusm-motor.toml", sets, root / f"homogeneity_{name}",
                                             None)["motor"]
    finally:
        if old is None:
            os.environ.pop("PIEZODYN_CACHE_DIR")
        else:
            os.environ["PIEZODYN_CACHE_DIR"] = old
    base, scaled, collapsed = runs["base"], runs["scaled"], runs["preload_only"]
    for key in ("speed_rad_per_s", "normal_force_N", "rotor_axial_offset_m"):
        assert scaled[key] == pytest.approx(scale * base[key], rel=2e-3), key
    assert scaled["contact_point_amplitude_m"]["normal"] == pytest.approx(
        scale * base["contact_point_amplitude_m"]["normal"], rel=2e-3)
    for key in ("electrical_power_W", "friction_loss_W", "damping_loss_W"):
        assert scaled[key] == pytest.approx(scale**2 * base[key], rel=2e-3), key
    for key, value in base["fractions"].items():
        assert scaled["fractions"][key] == pytest.approx(value, abs=5e-3), key
    # the same preload at the unscaled voltage: the rotor lies on the ring and the wave is gone
    assert base["fractions"]["separation"] > 0.7 > 0.2 > collapsed["fractions"]["separation"]
    assert collapsed["contact_point_amplitude_m"]["normal"] < 0.1 * base["contact_point_amplitude_m"]["normal"]
    assert abs(collapsed["speed_rad_per_s"]) < 0.1 * abs(base["speed_rad_per_s"])
