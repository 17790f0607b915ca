"""The lumped travelling-wave motor (``[lumped]`` with ``model = "friction_drive"``): the stator's wave mode, a
rigid rotor and the rigid-Winkler friction-drive law (app/references/friction_drive.py), solved for the steady
operating point (docs/lumped-motor.md).

Model. The stator's wave is a degenerate pair of modes of order n, each a 1-DOF oscillator whose coordinate is the
normal amplitude at the contact circle: mass m_m = k_m / omega_m^2, stiffness k_m, damping c_m = 2 zeta k_m /
omega_m, drive force F_d = (F_m per volt) x V. Driven 90 deg apart they make the travelling wave w = a cos xi,
u = rho a sin xi (rho = U_t / W) round the circle of radius r_c. A rigid cone rotor presses on a Winkler layer of
stiffness k_w per area across the contact width b with N = P / sin(alpha); Coulomb mu; no tangential compliance,
quasi-static (the law's assumptions). In the frame of the wave nothing depends on time, so the steady state is
one algebraic problem, not a time integration:

* the crests carry N over |xi| < theta_c: N = 2 k_w a b r_c B(theta_c) (the law's N per wavelength times n,
  k = n / r_c: n cancels);
* the pressure's first harmonic stiffens each mode by dk = k_w b r_c C(theta_c) (``crest_harmonic``);
* the friction damps it: both modes together lose c_eq omega^2 a^2 = F V + D to the rotor, F V the shaft power
  and D the friction loss (the law's ``dissipated_power_per_length`` x 2 pi r_c b);
* the rotor's speed V = Omega r_c follows from the load T: F/(mu N) = T / (mu N r_c), the law's
  ``speed_for_force`` (no load: ``no_load_speed``; held: V = 0);
* each mode: a |k_m + dk - m_m omega^2 + i omega (c_m + c_eq)| = F_d.

The last line is one equation in the wave amplitude a (everything else follows from a). It can have two roots on
the crests (theta_c < pi): the contact's stiffening dk ~ N / a falls as the wave grows, so a drive above the
mode's resonance meets it twice. Every root is found (a scan of a between the smallest wave that lifts the rotor
off the troughs and the resonant amplitude F_d / (omega c_m), then Brent). A root is stable if the slow flow
(the pair's averaged complex amplitude and the rotor's spin, :func:`slow_flow_rates`) linearised there has no
growing eigenvalue; at the roots measured this is where the residual rises with a, and a saddle (one growing
eigenvalue, the middle root of three) where it falls (tests/test_lumped_motor.py). ``branch``: 'upper' is the
largest root, 'lower' the smallest of two or more. Without a root the wave cannot carry the preload on its
crests (the rotor lies on the whole ring: the law does not apply).

Why no time loop: the law is quasi-static and the steady travelling wave is stationary in its frame, so the run
loop would only relax, period by period, to this fixed point (and could not tell the saddle). The rotor's
inertia enters only the start-up time constant I Omega_0 / T_stall, reported. Units: SI throughout."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import brentq

from app.references import friction_drive as law

#: the amplitude scan's points (log-spaced) between the smallest riding wave and the resonant amplitude
SCAN_POINTS = 240


@dataclass(frozen=True)
class MotorParameters:
    """SI parameters of the lumped motor (from a ``FrictionDriveSection``)."""

    omega_m: float          # the mode's angular frequency [rad/s]
    k_m: float              # modal stiffness referred to W [N/m]
    c_m: float              # modal damping [N s/m]
    m_m: float              # modal mass [kg]
    drive_force_N: float    # F_d per mode [N]
    rho: float              # U_t / W
    omega: float            # drive [rad/s]
    preload_N: float
    normal_force_N: float   # N = P / sin(alpha)
    mu: float               # the acting coefficient (mu_d x FACT: mu_s at every slip speed)
    mu_dynamic: float
    k_w: float              # [Pa/m]
    width_m: float
    radius_m: float
    sin_alpha: float
    inertia_kg_m2: float

    def to_report(self) -> dict:
        """The parameters under names that carry their units (summary.json)."""
        names = {"omega_m": "mode_angular_frequency_rad_per_s", "k_m": "modal_stiffness_N_per_m",
                 "c_m": "modal_damping_N_s_per_m", "m_m": "modal_mass_kg", "rho": "tangential_ratio",
                 "omega": "drive_angular_frequency_rad_per_s", "mu": "friction_coefficient",
                 "mu_dynamic": "friction_coefficient_dynamic", "k_w": "winkler_stiffness_Pa_per_m",
                 "sin_alpha": "sin_half_angle"}
        return {names.get(k, k): v for k, v in asdict(self).items()}


def derive_parameters(section) -> MotorParameters:
    """The SI parameters of ``section`` (a FrictionDriveSection), the stator's from its modal summary file if
    ``stator.source = 'modal_summary'``."""
    from app.case.lumped import load_modal_summary

    st = section.stator
    mode = {"resonance_frequency_Hz": st.resonance_frequency_Hz, "modal_stiffness_N_per_m": st.modal_stiffness_N_per_m,
            "damping_ratio": st.damping_ratio, "force_per_volt_N_per_V": st.force_per_volt_N_per_V}
    if st.source == "modal_summary":
        mode = load_modal_summary(st.modal_summary_file, None, "lumped.stator.modal_summary_file")
    omega_m = 2 * math.pi * mode["resonance_frequency_Hz"]
    k_m = mode["modal_stiffness_N_per_m"]
    c = section.contact
    sin_a = math.sin(math.radians(c.half_angle_deg))
    return MotorParameters(
        omega_m=omega_m, k_m=k_m, c_m=2 * mode["damping_ratio"] * k_m / omega_m, m_m=k_m / omega_m**2,
        drive_force_N=mode["force_per_volt_N_per_V"] * section.drive.voltage_amplitude_V, rho=st.tangential_ratio,
        omega=2 * math.pi * section.drive.frequency_Hz, preload_N=section.rotor.preload_N,
        normal_force_N=section.rotor.preload_N / sin_a, mu=c.mu_dynamic * c.static_ratio, mu_dynamic=c.mu_dynamic,
        k_w=c.stiffness_Pa_per_m, width_m=c.width_m, radius_m=c.radius_m, sin_alpha=sin_a,
        inertia_kg_m2=section.rotor.inertia_kg_m2)


def free_amplitude(p: MotorParameters) -> float:
    """The wave's normal amplitude without the rotor [m]."""
    return p.drive_force_N / abs(p.k_m - p.m_m * p.omega**2 + 1j * p.omega * p.c_m)


def smallest_riding_amplitude(p: MotorParameters) -> float:
    """Below this wave amplitude the preload presses the rotor onto the troughs too (theta_c = pi) [m]."""
    return p.normal_force_N / (2 * p.k_w * p.width_m * p.radius_m * law.contact_integral(math.pi))


def contact_half_angle(p: MotorParameters, a: float) -> float:
    """theta_c carrying N on a wave of amplitude a (the law's per-wavelength form with one wavelength round the
    ring and unit depth: the total is independent of the order n)."""
    return law.contact_half_angle(p.normal_force_N / p.width_m, p.k_w, a, 1.0 / p.radius_m)


def state(p: MotorParameters, a: float, load_ratio: float | None) -> dict:
    """Everything at wave amplitude ``a`` with the rotor under ``load_ratio`` = T / (mu N r_c) in [0, 1)
    (None: held, V = 0): theta_c, the speeds, the contact's stiffening and damping, and the amplitude equation's
    residual a |Z| - F_d [N]."""
    theta_c = contact_half_angle(p, a)
    surface = p.omega * p.rho * a                        # omega U_t
    if load_ratio is None:
        speed = 0.0
    elif load_ratio == 0.0:
        speed = law.no_load_speed(surface, theta_c)
    else:
        speed = law.speed_for_force(load_ratio, surface, theta_c)
    ratio = law.force_ratio(speed, surface, theta_c)      # F / (mu N): 1 when held
    force = p.mu * p.normal_force_N * ratio
    ring = 2 * math.pi * p.radius_m * p.width_m            # contact area swept by the wave [m^2]
    friction_loss = law.dissipated_power_per_length(speed, surface, theta_c, p.mu, p.k_w, a) * ring
    shaft = force * speed
    c_eq = (shaft + friction_loss) / (p.omega * a) ** 2
    stiffening = p.k_w * p.width_m * p.radius_m * law.crest_harmonic(theta_c)
    impedance = p.k_m + stiffening - p.m_m * p.omega**2 + 1j * p.omega * (p.c_m + c_eq)
    return {"amplitude_m": a, "theta_c": theta_c, "surface_speed_m_per_s": surface, "speed_m_per_s": speed,
            "force_ratio": float(ratio), "force_N": force, "shaft_power_W": shaft, "friction_loss_W": friction_loss,
            "contact_damping_N_s_per_m": c_eq, "stiffening_N_per_m": stiffening, "impedance": impedance,
            "residual_N": a * abs(impedance) - p.drive_force_N}


def slow_flow_rates(p: MotorParameters, x: np.ndarray, load_torque_N_m: float, held: bool) -> np.ndarray:
    """d/dt of the slow state x = (Re X, Im X, Omega): the complex amplitude X of each mode of the pair (x =
    Re(X e^{i omega t}), the travelling wave kept) averaged over a period, 2 i omega m_m dX/dt = F_d - Z(|X|,
    Omega) X (the second derivative and c dX/dt neglected: slow against omega), and the rotor's spin,
    I dOmega/dt = T_f(|X|, Omega) - T (0 when held)."""
    amplitude = complex(x[0], x[1])
    a = abs(amplitude)
    theta_c = contact_half_angle(p, a)
    surface = p.omega * p.rho * a
    speed = x[2] * p.radius_m
    force = p.mu * p.normal_force_N * law.force_ratio(speed, surface, theta_c)
    loss = law.dissipated_power_per_length(speed, surface, theta_c, p.mu, p.k_w, a) * 2 * math.pi * p.radius_m \
        * p.width_m
    c_eq = (force * speed + loss) / (p.omega * a) ** 2
    impedance = (p.k_m + p.k_w * p.width_m * p.radius_m * law.crest_harmonic(theta_c) - p.m_m * p.omega**2
                 + 1j * p.omega * (p.c_m + c_eq))
    rate = (p.drive_force_N - impedance * amplitude) / (2j * p.omega * p.m_m)
    spin = 0.0 if held else (force * p.radius_m - load_torque_N_m) / p.inertia_kg_m2
    return np.array([rate.real, rate.imag, spin])


def slow_flow_eigenvalues(p: MotorParameters, root: dict, load_torque_N_m: float, held: bool) -> np.ndarray:
    """Eigenvalues [1/s] of the slow flow (:func:`slow_flow_rates`) linearised at a root (central differences,
    steps 1e-6 of the state's scale); the spin drops out when held."""
    amplitude = p.drive_force_N / root["impedance"]
    x0 = np.array([amplitude.real, amplitude.imag, root["speed_m_per_s"] / p.radius_m])
    n = 2 if held else 3
    scales = [abs(amplitude), abs(amplitude), max(x0[2], p.omega * p.rho * abs(amplitude) / p.radius_m)]
    jacobian = np.zeros((n, n))
    for j in range(n):
        step = np.zeros(3)
        step[j] = 1e-6 * scales[j]
        jacobian[:, j] = ((slow_flow_rates(p, x0 + step, load_torque_N_m, held)
                           - slow_flow_rates(p, x0 - step, load_torque_N_m, held)) / (2 * step[j]))[:n]
    return np.linalg.eigvals(jacobian)


def roots(p: MotorParameters, load_ratio: float | None) -> list[dict]:
    """Every wave amplitude on the crests that satisfies the amplitude equation under ``load_ratio`` (see
    :func:`state`), largest first, each with ``stable`` (the residual rises with a there)."""
    lo = smallest_riding_amplitude(p) * (1 + 1e-9)
    hi = p.drive_force_N / (p.omega * p.c_m) * 1.001       # |Z| >= omega c_m while the rotor takes power
    if hi <= lo:
        return []
    grid = np.geomspace(lo, hi, SCAN_POINTS)
    values = [state(p, a, load_ratio)["residual_N"] for a in grid]
    found = []
    for i in range(len(grid) - 1):
        if values[i] == 0.0 or values[i] * values[i + 1] < 0:
            a = grid[i] if values[i] == 0.0 else brentq(lambda x: state(p, x, load_ratio)["residual_N"], grid[i],
                                                        grid[i + 1], xtol=1e-16, rtol=1e-13)
            root = state(p, a, load_ratio)
            root["residual_rises"] = bool(values[i + 1] > values[i])
            held = load_ratio is None
            torque = 0.0 if held else load_ratio * p.mu * p.normal_force_N * p.radius_m
            eigenvalues = slow_flow_eigenvalues(p, root, torque, held)
            root["slow_flow_growth_rate_per_s"] = float(eigenvalues.real.max())
            root["stable"] = bool(eigenvalues.real.max() < 0)
            found.append(root)
    return found[::-1]


def operating_point(p: MotorParameters, root: dict, load_torque_N_m: float) -> dict:
    """The operating point of one root in the motor's keys (the same names as the FE and modal tiers'
    ``statistics.motor``), plus the lumped model's own (wave amplitude, contact angle, stiffening, ...)."""
    a, theta_c = root["amplitude_m"], root["theta_c"]
    speed = root["speed_m_per_s"] / p.radius_m
    torque = root["force_N"] * p.radius_m
    # electrical input = the drive's work on both modes: 2 x 1/2 Re(F_d conj(i omega X)), X = F_d / Z
    x = p.drive_force_N / root["impedance"]
    electrical = float((p.drive_force_N * np.conj(1j * p.omega * x)).real)
    damping = p.c_m * (p.omega * a) ** 2
    output = load_torque_N_m * speed
    balance = electrical - (damping + root["friction_loss_W"] + root["shaft_power_W"])
    surface = root["surface_speed_m_per_s"]
    phi = math.acos(min(max(root["speed_m_per_s"] / surface, -1.0), 1.0)) if surface > 0 else 0.0
    forward = min(phi, theta_c) / math.pi
    n_force = p.normal_force_N
    return {
        "speed_rad_per_s": speed, "speed_rpm": speed * 60.0 / (2 * math.pi),
        "speed_change_over_window_rad_per_s": 0.0,
        "load_torque_N_m": load_torque_N_m, "friction_torque_N_m": torque,
        "output_power_W": output, "shaft_power_W": root["shaft_power_W"], "electrical_power_W": electrical,
        "efficiency": output / electrical if electrical > 0 else 0.0,
        "friction_loss_W": root["friction_loss_W"], "damping_loss_W": damping, "stored_energy_change_J": 0.0,
        "energy_balance_relative": balance / electrical if electrical else 0.0,
        "normal_force_N": n_force, "normal_force_closed_form_N": n_force, "axial_force_N": p.preload_N,
        "contact_radius_m": p.radius_m,
        "coulomb_torque_bound_N_m": p.mu * n_force * p.radius_m,
        "kinetic_friction_torque_N_m": p.mu_dynamic * n_force * p.radius_m,
        # the rotor's face sits at w = a cos theta_c along the face normal, whose axial part is sin(alpha)
        "rotor_axial_offset_m": a * math.cos(theta_c) / p.sin_alpha, "rotor_axial_vibration_m": 0.0,
        "fractions": {"separation": 1.0 - theta_c / math.pi, "stick": 0.0, "forward_slip": forward,
                      "backward_slip": theta_c / math.pi - forward},
        "contact_point_amplitude_m": {"normal": a, "tangential": p.rho * a},
        # the lumped model's own
        "wave_amplitude_m": a, "tangential_amplitude_m": p.rho * a, "contact_half_angle_rad": theta_c,
        "surface_speed_m_per_s": surface, "speed_over_surface_speed": root["speed_m_per_s"] / surface,
        "contact_stiffening_N_per_m": root["stiffening_N_per_m"],
        "contact_damping_N_s_per_m": root["contact_damping_N_s_per_m"],
        "stable": root["stable"], "slow_flow_growth_rate_per_s": root["slow_flow_growth_rate_per_s"],
    }


def _pick(found: list[dict], branch: str) -> dict | None:
    if not found:
        return None
    return found[0] if branch == "upper" else found[-1] if len(found) > 1 else None


def solve(section) -> dict:
    """The lumped motor's results: the operating point at the section's load (``operating_point``, None where
    the wave cannot carry the rotor on the chosen branch), every root there (``branches``), the speed-torque
    curve of each branch from no load to stall (``curves``), the no-load speed and stall torque, and the wall
    time per point."""
    start = time.perf_counter()
    p = derive_parameters(section)
    bound = p.mu * p.normal_force_N * p.radius_m            # the law's stall torque
    load = section.rotor.load_torque_N_m
    ratio = None if load >= bound else load / bound
    here = roots(p, ratio)
    point = _pick(here, section.branch)
    n = section.curve_points
    curves = {"upper": [], "lower": []}
    evaluated = 1
    for k in range(n):
        torque = bound * k / (n - 1)
        found = roots(p, None if k == n - 1 else k / (n - 1))
        evaluated += 1
        for branch in curves:
            root = _pick(found, branch)
            if root is not None:
                curves[branch].append(operating_point(p, root, torque))
    wall = time.perf_counter() - start
    free = free_amplitude(p)
    upper = curves["upper"]
    no_load = upper[0]["speed_rad_per_s"] if upper and upper[0]["load_torque_N_m"] == 0.0 else None
    results = {
        "tier": "lumped", "model": "friction_drive", "branch": section.branch,
        "parameters": p.to_report(),
        "free_wave_amplitude_m": free, "free_surface_speed_m_per_s": p.omega * p.rho * free,
        "smallest_riding_amplitude_m": smallest_riding_amplitude(p),
        "modal_force_N": p.drive_force_N,
        "normal_force_over_modal_force": p.normal_force_N / p.drive_force_N,    # N / F_m (F_m = 2 zeta k_m W)
        "operating_point": operating_point(p, point, load) if point is not None else None,
        "riding": point is not None,
        "branches": [operating_point(p, r, load) for r in here],
        "curves": curves,
        "no_load_speed_rad_per_s": no_load,
        "no_load_speed_rpm": no_load * 60 / (2 * math.pi) if no_load is not None else None,
        "stall_torque_N_m": bound if upper and upper[-1]["load_torque_N_m"] == bound else None,
        "start_up_time_constant_s": p.inertia_kg_m2 * no_load / bound if no_load is not None else None,
        "points_solved": evaluated, "wall_time_s": wall, "wall_s_per_point": wall / evaluated,
    }
    return results


def check(case) -> None:
    """``validate``: what the solve derives from the section before it solves (the stator's mode from its modal
    summary file, when given so); every other rule is the section's own (app/case/lumped.py)."""
    derive_parameters(case.lumped)
