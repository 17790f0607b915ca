"""The lumped motor (tier lumped, ``[lumped] model = "friction_drive"``, app/lumped/friction_drive.py): the wave
mode + rigid rotor + friction-drive law, solved for the steady point (docs/lumped-motor.md).

References: an independent quadrature of the rigid-Winkler contact over one wavelength (the law derived again on a
grid, not through app/references/friction_drive.py), the law's closed forms (stall mu N r_c, the no-load deficit
about 0.06 theta_c^2), the small-angle amplitude equation (the contact stiffens the mode by about N / a), the
energy balance, and the documented conventions (the motor scene's keys, one line per bad input)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from app.case.lumped import FrictionDriveSection
from app.case.validate import from_dict
from app.errors import CaseError
from app.lumped import friction_drive as fd
from app.references.friction_drive import crest_harmonic

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "wwusm-motor-lumped.toml"
serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: in-process runs and CLI subprocesses")


def section(**over) -> FrictionDriveSection:
    data = {"model": "friction_drive", "curve_points": 3}
    data.update(over)
    return from_dict(FrictionDriveSection, data, "case.toml", "lumped")


# ---------------------------------------------------------------- an independent rigid-Winkler contact on a grid
XI = np.linspace(-math.pi, math.pi, 2_000_001)
DXI = XI[1] - XI[0]


def grid_half_angle(normal_per_area_Pa: float, k_w: float, a: float) -> float:
    """theta_c where the mean over a wavelength of k_w a (cos xi - cos theta_c)_+ equals the mean pressure, by
    bisection on grid sums."""
    lo, hi = 1e-6, math.pi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        mean = np.sum(np.clip(np.cos(XI) - math.cos(mid), 0, None)) * DXI / (2 * math.pi) * k_w * a
        lo, hi = (mid, hi) if mean < normal_per_area_Pa else (lo, mid)
    return 0.5 * (lo + hi)


def grid_force_ratio(v_over_surface: float, theta_c: float) -> float:
    """F / (mu N) from the grid: the friction force mu p sign(surface speed - V) over the pressure."""
    p = np.clip(np.cos(XI) - math.cos(theta_c), 0, None)
    return float(np.sum(p * np.sign(np.cos(XI) - v_over_surface)) / np.sum(p))


def test_crest_harmonic_is_the_first_harmonic_of_the_crest_pressure():
    """Reference: the grid integral of (cos xi - cos theta_c)_+ cos xi. Tolerance 1e-9: the trapezoid on 2e6
    intervals of an integrand with a kink at +-theta_c (error ~ h^2 ~ 1e-11 times its slope jump)."""
    for theta_c in (0.05, 0.15, 1.0, 2.5):
        grid = np.sum(np.clip(np.cos(XI) - math.cos(theta_c), 0, None) * np.cos(XI)) * DXI
        assert crest_harmonic(theta_c) == pytest.approx(grid, rel=1e-9, abs=0)


def test_prescribed_wave_limit_reproduces_the_law():
    """A stator 1e6 times stiffer with the same free wave (k_m and F_m both x 1e6: the contact's stiffening
    and damping are 1e-6 of the mode's) is the law's prescribed travelling wave. References: the grid contact
    (independent of the law's module) for theta_c and for the no-load speed (bisection on the grid's force),
    stall = mu N r_c, and the deficit about 0.06 theta_c^2. Tolerances: the wave within 1e-5 (the neglected
    contact terms are ~1e-6 of |Z|); the deficit within 1 % of the grid's (the grid resolves V / (omega U_t)
    to ~1e-7 against a deficit of 1.3e-3: 1e-4 relative, plus the 1e-6 wave change); the small-angle form within
    3 % (its next term is O(theta_c^4), 0.2 % at theta_c = 0.15; measured 0.6 %)."""
    base = section()
    stiff = section(stator={"modal_stiffness_N_per_m": base.stator.modal_stiffness_N_per_m * 1e6,
                            "force_per_volt_N_per_V": base.stator.force_per_volt_N_per_V * 1e6},
                    curve_points=2)
    p = fd.derive_parameters(stiff)
    free = fd.free_amplitude(p)
    result = fd.solve(stiff)
    point = result["operating_point"]
    assert point["wave_amplitude_m"] == pytest.approx(free, rel=1e-5, abs=0)
    mean_pressure = p.normal_force_N / (2 * math.pi * p.radius_m * p.width_m)
    theta_c = grid_half_angle(mean_pressure, p.k_w, point["wave_amplitude_m"])
    assert point["contact_half_angle_rad"] == pytest.approx(theta_c, rel=1e-6, abs=0)
    lo, hi = math.cos(theta_c), 1.0                 # F = mu N below omega U_t cos theta_c, -mu N above omega U_t
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if grid_force_ratio(mid, theta_c) > 0 else (lo, mid)
    deficit = 1 - 0.5 * (lo + hi)
    lumped_deficit = 1 - point["speed_over_surface_speed"]
    assert lumped_deficit == pytest.approx(deficit, rel=1e-2, abs=0)
    assert lumped_deficit == pytest.approx(0.06 * theta_c**2, rel=0.03, abs=0)
    surface = p.omega * p.rho * point["wave_amplitude_m"]
    assert point["speed_rad_per_s"] * p.radius_m == pytest.approx(surface * (1 - deficit), rel=1e-4, abs=0)
    stall = result["curves"]["upper"][-1]
    assert stall["speed_rad_per_s"] == 0.0
    assert stall["friction_torque_N_m"] == pytest.approx(p.mu * p.preload_N / math.sin(math.radians(15)) * p.radius_m,
                                                         rel=1e-12, abs=0)


def test_upper_wave_against_the_small_angle_amplitude_equation():
    """With friction 1e-6 of the case's (no power drawn) the wave obeys a |k_m + dk - m omega^2 + i omega c_m| = F_d
    with dk a = N C / (2 B) -> N for small theta_c: (N - |d| a)^2 + (omega c_m a)^2 = F_d^2, d = k_m - m omega^2 < 0
    (drive above the mode), a quadratic whose larger root is the upper wave. Tolerance 1 %: C / (2 B) = 1 +
    theta_c^2 / 10 + ... (0.2 % at theta_c = 0.15) moves the root by (N / |d| a) times that. A stiffening off by a
    factor (2 dk, or dk = 0: the free 7.44 um) misses by 30-40 %. At 0.98 N and no load this root is the only one."""
    s = section(contact={"mu_dynamic": 0.57e-6})
    p = fd.derive_parameters(s)
    found = fd.roots(p, 0.0)
    assert len(found) == 1
    d = p.k_m - p.m_m * p.omega**2
    assert d < 0
    N, F, wc = p.normal_force_N, p.drive_force_N, p.omega * p.c_m
    A, B, C = d**2 + wc**2, 2 * N * d, N**2 - F**2            # A a^2 + B a + C = 0 (d < 0: B < 0)
    upper = (-B + math.sqrt(B * B - 4 * A * C)) / (2 * A)
    assert found[0]["amplitude_m"] == pytest.approx(upper, rel=0.01, abs=0)
    assert found[0]["stable"]


def test_every_point_closes_its_energy_balance():
    """Reference: energy. The electrical input is the drive's work on both modes, 1/2 Re(F_d conj(i omega X)) each,
    X = F_d / Z; it equals damping + friction loss + shaft power only if the solved amplitude is a root (|X| = a).
    Tolerance 1e-9: the root is solved to 1e-13 relative. Loads from 0 to stall on both branches, and at 1.2 N where
    the three roots coexist at no load."""
    for s in (section(curve_points=9), section(rotor={"preload_N": 1.2}, curve_points=3)):
        result = fd.solve(s)
        points = result["curves"]["upper"] + result["curves"]["lower"] + result["branches"]
        assert points
        for point in points:
            assert abs(point["energy_balance_relative"]) < 1e-9
            assert point["electrical_power_W"] > 0



def test_slow_flow_stability_follows_the_saddle_node_picture():
    """Reference: the saddle-node picture of a forced oscillator whose stiffness depends on its amplitude (the
    turning points of a(F_d) are where d(a|Z|)/da = 0: a root where a|Z| - F_d falls with a is a saddle). The code
    decides stability from the eigenvalues of the slow flow linearised at the root (amplitude and the rotor's spin,
    finite differences): the two must agree at every root, no load, under load and held; 1.2 N has three roots at
    no load (stable, saddle, stable). No tolerance: a sign."""
    three = fd.solve(section(rotor={"preload_N": 1.2}))["branches"]
    assert [b["stable"] for b in three] == [True, False, True]     # upper, saddle, lower
    for s in (section(rotor={"preload_N": 1.2}), section(rotor={"preload_N": 0.98})):
        p = fd.derive_parameters(s)
        for ratio in (0.0, 0.5, None):
            for root in fd.roots(p, ratio):
                assert root["stable"] == root["residual_rises"], (s.rotor.preload_N, ratio, root["amplitude_m"])


def test_the_wave_cannot_carry_four_newtons_at_400_Vpp():
    """The documented collapse (docs/motor-rotor.md, "4.116 N at 400 Vpp collapses"): with N / F_m = 4.4 the
    amplitude equation has no root with the rotor on the crests (theta_c < pi): the run reports no operating point
    rather than one outside the law."""
    result = fd.solve(section(rotor={"preload_N": 4.116}))
    assert result["normal_force_over_modal_force"] == pytest.approx(4.116 / math.sin(math.radians(15)) / 3.6228,
                                                                    rel=1e-3)
    assert not result["riding"] and result["operating_point"] is None and result["branches"] == []


@serial
def test_the_case_reports_the_motor_keys_of_every_tier(tmp_path):
    """Convention (docs/motor-rotor.md, "What a run reports"): statistics.motor carries the keys the FE and modal
    tiers report, the speed-torque CSV is written, and speed falls with load on the upper branch (the wave shrinks
    as the rotor draws power: docs/lumped-motor.md)."""
    from app.runner import run_case

    summary = run_case(CASE, out_dir=tmp_path / "run", quiet=True)
    lumped = summary["results"]["lumped"]
    motor = lumped["statistics"]["motor"]
    for key in ("speed_rad_per_s", "speed_rpm", "load_torque_N_m", "friction_torque_N_m", "output_power_W",
                "shaft_power_W", "electrical_power_W", "efficiency", "friction_loss_W", "damping_loss_W",
                "energy_balance_relative", "normal_force_N", "normal_force_closed_form_N", "axial_force_N",
                "coulomb_torque_bound_N_m", "kinetic_friction_torque_N_m", "contact_radius_m",
                "rotor_axial_offset_m", "rotor_axial_vibration_m", "fractions", "contact_point_amplitude_m"):
        assert key in motor, key
    assert set(motor["fractions"]) == {"separation", "stick", "forward_slip", "backward_slip"}
    assert sum(motor["fractions"].values()) == pytest.approx(1.0, abs=1e-12)
    assert motor["speed_rpm"] == pytest.approx(lumped["no_load_speed_rpm"], rel=1e-12)
    assert "motor_speed_torque.csv" in summary["outputs"]
    rows = np.loadtxt(tmp_path / "run" / "motor_speed_torque.csv", delimiter=",", skiprows=1)
    upper = rows[rows[:, 0] == 0]
    assert len(upper) == 9
    assert np.all(np.diff(upper[:-1, 2]) < 0)       # speed_rpm falls with load (the last row: held)


def test_modal_summary_source_gives_the_typed_stator(tmp_path):
    """Convention: stator.source = "modal_summary" reads results.modal.contact_force of a stator run (the pair's
    mean frequency, k_m, zeta, F_m per volt). A summary holding the typed values gives the typed run's point
    (to round-off); a summary without contact_force is refused naming the key."""
    s = section()
    st = s.stator
    summary = {"results": {"modal": {"contact_force": {
        "modes": [{"frequency_Hz": st.resonance_frequency_Hz - 0.5}, {"frequency_Hz": st.resonance_frequency_Hz + 0.5}],
        "modal_force_per_volt_N_per_V": st.force_per_volt_N_per_V,
        "modal_stiffness_N_per_m": st.modal_stiffness_N_per_m, "damping_ratio": st.damping_ratio}}}}
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(summary))
    from_file = section(stator={"source": "modal_summary", "modal_summary_file": str(path)})
    a = fd.solve(s)["operating_point"]["speed_rpm"]
    b = fd.solve(from_file)["operating_point"]["speed_rpm"]
    assert b == pytest.approx(a, rel=1e-12)
    path.write_text(json.dumps({"results": {"modal": {}}}))
    with pytest.raises(CaseError) as info:
        section(stator={"source": "modal_summary", "modal_summary_file": str(path)})
    assert info.value.key == "lumped.stator.modal_summary_file"


@pytest.mark.parametrize("data, key", [
    ({"rotor": {"load_torque_N_m": 0.05}}, "lumped.rotor.load_torque_N_m"),     # above mu N r_c = 36 mN m
    ({"rotor": {"preload_N": 0.0}}, "lumped.rotor.preload_N"),
    ({"contact": {"half_angle_deg": 90.0}}, "lumped.contact.half_angle_deg"),
    ({"contact": {"mu_dynamic": 0.0}}, "lumped.contact.mu_dynamic"),
    ({"stator": {"damping_ratio": 0.0}}, "lumped.stator.damping_ratio"),
    ({"stator": {"source": "modal_summary"}}, "lumped.stator.modal_summary_file"),
    ({"stator": {"source": "modal_summary", "modal_summary_file": "none.json"}}, "lumped.stator.modal_summary_file"),
    ({"stator": {"modal_summary_file": "x.json"}}, "lumped.stator.modal_summary_file"),
    ({"branch": "middle"}, "lumped.branch"),
    ({"curve_points": 1}, "lumped.curve_points"),
])
def test_bad_input_names_the_key(data, key):
    """Convention (GUIDE): every bad input is one CaseError naming the file and the dotted key."""
    with pytest.raises(CaseError) as info:
        section(**data)
    assert info.value.key == key
    assert info.value.file == "case.toml"


@serial
@pytest.mark.parametrize("args, key", [
    (["--set", 'lumped={model="impact_chain"}'], "lumped.model"),    # the motor scene refuses the drill's model
    (["--set", 'lumped.model="impact_chain"'], "lumped.branch"),     # a key of the other model's table
    (["--set", 'lumped.model="lumped_motor"'], "lumped.model"),
    (["--set", "lumped.rotor.load_torque_N_m=1.0"], "lumped.rotor.load_torque_N_m"),
])
def test_cli_bad_input_is_one_line_and_exit_2(args, key):
    """Convention (GUIDE): one line naming the file and the key, exit status 2, no traceback."""
    run = subprocess.run([sys.executable, "-m", "app", "validate", str(CASE), *args], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert run.returncode == 2
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in run.stderr


@serial
def test_resume_is_refused_for_a_steady_solve(tmp_path):
    """Convention: --resume continues a time loop; a steady solve has none (one line naming --resume)."""
    from app.runner import load_for_run

    with pytest.raises(CaseError) as info:
        load_for_run(CASE, None, resume=True)
    assert info.value.key == "--resume"
