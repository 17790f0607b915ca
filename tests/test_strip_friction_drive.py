"""The travelling-wave friction drive in the FE and modal tiers against its semi-analytic law (issues 11, 22).

cases/validation/strip-friction-drive.toml: a thin stiff strip (plane strain, one wavelength) whose
bottom carries a prescribed travelling wave ([[transient.base_motions]]), under a rigid flat slider
held at a fixed height and moving at a prescribed speed V against the wave, with Coulomb friction
(mu = 0.57) and a penalty contact. Reference (app/references/friction_drive.py): the slider on a Winkler
layer under the wave w = W_s cos xi, u = U_s sin xi of the strip's top face, crests in contact over
|xi| < theta_c with cos theta_c = (slider height above the top face) / W_s:

    N = 2 k_w W_s B(theta_c) / k per wavelength and depth,     F / (mu N) = 2 A(V) / B - 1.

W_s, U_s are the top face's amplitudes (thin-layer kinematics) and k_w the penalty in series with
the strip's through-thickness stiffness; everything is read from the case file. The issue asks for
the mean drive force within 5 %: here within 0.05 mu N at every speed (near the no-load speed the
force passes through zero, so the error is measured against the force scale mu N), the normal force
within 5 %, and the deficit of the no-load speed 1 - V0 / (omega U_s) within 5 %. Measured
(serial, FE tier): force ratio within 0.009 of the law,
N 0.2 % low, deficit of the no-load speed 1.8 % above the law. The modal tier runs the same case (its
base motion as four pattern inputs of the reduced strip, the top face's nodes as contact sites) against the
same law and tolerances.
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from scipy.optimize import brentq

from app.case.schema import load_case
from app.references import friction_drive as fd
from app.runner import run_case

CASE = Path(__file__).resolve().parents[1] / "cases" / "validation" / "strip-friction-drive.toml"
MEASURED_PERIODS = 4        # the last four of eight periods (two of ramp, two settling)


def reference():
    """Parameters of the law, read from the case file (SI)."""
    case = load_case(CASE)
    tr = case.transient
    wave, slider, contact = tr.base_motions[0], tr.bodies[0], tr.contacts[0]
    carrier = case.materials[case.regions[0].material]
    h = case.geometry.parameters["length_m"]
    k = 2 * math.pi / wave.wavelength_m
    omega = 2 * math.pi * tr.drive.frequency_Hz
    w_s, u_s = fd.layer_surface_amplitudes(wave.normal_amplitude_m, wave.tangential_amplitude_m, k, h,
                                           carrier.poisson)
    theta_c = math.acos((slider.position_m[1] - h) / w_s)
    k_w = fd.layer_winkler(contact.stiffness, h, carrier.young_Pa, carrier.poisson)
    depth = case.geometry.thickness_m
    normal_N = 2 * k_w * w_s * fd.contact_integral(theta_c) / k * depth    # one wavelength
    return dict(surface_speed=omega * u_s, theta_c=theta_c, normal_N=normal_N, mu=contact.friction.mu_dynamic,
                period_s=1 / tr.drive.frequency_Hz, winkler=k_w, amplitude=w_s,
                length_m=wave.wavelength_m * depth)        # wave length times depth [m^2]


REF = reference()


def mean_forces(tmp_path, name: str, speed_ratio: float, overrides=(), tier: str = "fe") -> tuple[float, float, dict]:
    """(normal force N, drive force F (along the drive direction -x), run results) on the slider,
    averaged over the last periods, slider speed V = speed_ratio * omega U_s; the results get the
    mean power the contact dissipated over those periods, ``dissipated_W``."""
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / name if comm.rank == 0 else None, root=0)
    speed = speed_ratio * REF["surface_speed"]
    sets = [f"transient.bodies[0].velocity_m_per_s=[{-speed!r}, 0.0]", f'tier="{tier}"', *overrides]
    case = load_case(CASE, sets)
    results = run_case(CASE, sets, folder, comm=comm, quiet=True)["results"]["transient"]
    with h5py.File(folder / "transient.h5", "r") as f:
        t, force = f["time_s"][()], f["strip_slider_force_N"][()]
        dissipated = f["strip_slider_dissipated_J"][()]
    start = case.transient.end_time_s - MEASURED_PERIODS * REF["period_s"]
    window = t >= start - 1e-12
    tw = t[window]
    results["dissipated_W"] = (dissipated[-1] - dissipated[window][0]) / (tw[-1] - tw[0])

    def mean(y):
        return np.trapz(y[window], tw) / (tw[-1] - tw[0])

    # force on the slider: +z pushes it off the strip (the normal force), -x drives it
    return mean(force[:, 1]), -mean(force[:, 0]), results


@pytest.mark.parametrize("tier", ["fe", "modal"])
def test_mean_drive_force_follows_the_friction_drive_law(tmp_path, tier):
    ratios = [0.0, 0.5, 0.7, 0.85, 0.92, 0.95, 0.97, 1.2]
    measured = []
    for r in ratios:
        normal, drive, results = mean_forces(tmp_path, f"v{r}", r, tier=tier)
        assert results["cutbacks"] == 0
        law = fd.force_ratio(r * REF["surface_speed"], REF["surface_speed"], REF["theta_c"])
        measured.append(drive / (REF["mu"] * normal))
        print(f"V / (omega U_s) = {r:4.2f}: N = {normal:.4f} N (law {REF['normal_N']:.4f}), "
              f"F / (mu N) = {measured[-1]:+.4f} (law {law:+.4f})")
        assert normal == pytest.approx(REF["normal_N"], rel=0.05)
        assert abs(measured[-1] - law) <= 0.05
        # the friction power the contact reports (its dissipated energy) against the law's
        law_power = REF["length_m"] * fd.dissipated_power_per_length(
            r * REF["surface_speed"], REF["surface_speed"], REF["theta_c"], REF["mu"], REF["winkler"], REF["amplitude"])
        print(f"    dissipated {results['dissipated_W']:.5f} W (law {law_power:.5f} W)")
        assert results["dissipated_W"] == pytest.approx(law_power, rel=0.05)
    # stall and beyond the surface speed: the whole contact slides one way, |F| = mu N
    assert measured[0] == pytest.approx(1.0, abs=1e-3) and measured[-1] == pytest.approx(-1.0, abs=1e-3)
    # no-load speed: where the mean force changes sign. Between the bracketing speeds the FE curve is
    # the law plus an offset interpolated linearly (the law itself is too curved there for a
    # straight line through the two points: that alone would move V0 by 1e-3 omega U_s).
    i = next(j for j in range(len(ratios) - 1) if measured[j] > 0 >= measured[j + 1])
    a, b = ratios[i], ratios[i + 1]

    def law(v):
        return fd.force_ratio(v * REF["surface_speed"], REF["surface_speed"], REF["theta_c"])

    off_a, off_b = measured[i] - law(a), measured[i + 1] - law(b)
    v0 = brentq(lambda v: law(v) + off_a + (off_b - off_a) * (v - a) / (b - a), a, b)
    law_v0 = fd.no_load_speed(REF["surface_speed"], REF["theta_c"]) / REF["surface_speed"]
    print(f"no-load speed / (omega U_s): {v0:.5f} (law {law_v0:.5f}), deficit 1 - V0 / (omega U_s) "
          f"{1 - v0:.5f} (law {1 - law_v0:.5f})")
    # V0 is close to omega U_s whatever the contact does: its deficit is what the law predicts
    assert 1 - v0 == pytest.approx(1 - law_v0, rel=0.05)


@pytest.mark.mpi
def test_drive_force_at_one_speed_on_any_rank_count(tmp_path):
    """The shipped case's speed (0.95 omega U_s, in the steep part of the curve), serially and on 2
    ranks (the MPI suite): the same law, on half the mesh and six periods (MUMPS on 2 ranks)."""
    normal, drive, results = mean_forces(tmp_path, "v095", 0.95, ["geometry.parameters.lateral_divisions=50",
                                                                  "transient.end_time_s=1.5e-4"])
    law = fd.force_ratio(0.95 * REF["surface_speed"], REF["surface_speed"], REF["theta_c"])
    assert results["cutbacks"] == 0
    assert normal == pytest.approx(REF["normal_N"], rel=0.05)
    assert abs(drive / (REF["mu"] * normal) - law) <= 0.05


def test_top_face_moves_as_thin_layer_kinematics_say(tmp_path):
    """Without the slider the strip's top face carries W_s = W - nu/(1 - nu) k h U_t and
    U_s = U_t + k h W (friction_drive.layer_surface_amplitudes), the amplitudes the reference uses.
    Peaks are sampled 100 times per period: up to 5e-4 low; the first-order formula is good to
    (k h)^2 = 2.5e-4."""
    case = load_case(CASE)
    wave, h = case.transient.base_motions[0], case.geometry.parameters["length_m"]
    x = 0.25 * wave.wavelength_m
    points = [f'points.top_{c}={{coordinates_m=[{x}, {h}], component="{c}"}}' for c in ("x", "z")]
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / "free" if comm.rank == 0 else None, root=0)
    run_case(CASE, ["transient.contacts=[]", *points], folder, comm=comm, quiet=True)
    with h5py.File(folder / "transient.h5", "r") as f:
        t = f["time_s"][()]
        steady = t >= case.transient.end_time_s - MEASURED_PERIODS * REF["period_s"] - 1e-12
        amplitude = {c: np.ptp(f[f"top_{c}_displacement_m"][()][steady]) / 2 for c in ("x", "z")}
    carrier = case.materials[case.regions[0].material]
    w_s, u_s = fd.layer_surface_amplitudes(wave.normal_amplitude_m, wave.tangential_amplitude_m,
                                           2 * math.pi / wave.wavelength_m, h, carrier.poisson)
    assert amplitude["z"] == pytest.approx(w_s, rel=1e-3)
    assert amplitude["x"] == pytest.approx(u_s, rel=1e-3)
    # and the layer matters at this size: the formulas differ from the bottom's amplitudes by ~1 %
    assert abs(u_s / wave.tangential_amplitude_m - 1) > 5e-3


def test_travelling_wave_moves_along_its_direction_and_crests_against_it():
    """The prescribed field: the crest (xi = 0) advances along e at omega / k, and the surface at a
    crest moves along -e at omega U_t (what drives a slider against the wave)."""
    from app.transient.motions import TravellingWaveMotion, smooth_ramp

    k, omega, W, U = 2 * math.pi / 0.02, 2 * math.pi * 40e3, 1e-6, 1.5e-6
    x = np.linspace(0.0, 0.02, 2001)
    coords = np.column_stack([x, np.zeros_like(x)])
    dofs = np.arange(2 * x.size)
    motion = TravellingWaveMotion("w", dofs, np.repeat([0, 1], x.size), np.vstack([coords, coords]), W, U, k, omega,
                                  np.array([1.0, 0.0]), np.array([0.0, 1.0]), ramp_s=0.0)
    values = np.zeros(dofs.size)
    t, dt = 3e-6, 1e-10
    motion.set_values(t, values)
    crest = np.argmax(values[x.size:])
    assert x[crest] == pytest.approx(omega / k * t, abs=2e-5)             # xi = 0 there
    later = np.zeros(dofs.size)
    motion.set_values(t + dt, later)
    assert (later[crest] - values[crest]) / dt == pytest.approx(-omega * U, rel=1e-3)
    assert smooth_ramp(0.0, 1.0) == 0.0 and smooth_ramp(0.5, 1.0) == pytest.approx(0.5) and smooth_ramp(2.0, 1.0) == 1.0
