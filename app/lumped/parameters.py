"""From a validated ``LumpedSection`` to the SI numbers of eqs. 5-16, plus the closed forms used to
pick contact stiffness and damping (linearised Hertz, flat punch, Kelvin-Voigt restitution under
the force-zero opening rule)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from scipy.optimize import brentq

from app.case.lumped import ContactSection, LumpedSection, load_circuit

DEFAULT_TIP_AMPLITUDE_m = 15e-6
CONTACT_NAMES = ("tip_ball", "ball_stem", "stem_rock")


def effective_modulus_Pa(e_upper_Pa: float, nu_upper: float, e_lower_Pa: float, nu_lower: float) -> float:
    """Hertz contact modulus E* with 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2."""
    return 1.0 / ((1.0 - nu_upper**2) / e_upper_Pa + (1.0 - nu_lower**2) / e_lower_Pa)


def hertz_secant_stiffness_N_per_m(radius_m: float, modulus_Pa: float, force_N: float) -> float:
    """Secant stiffness F/delta of a sphere on a flat, F = 4/3 E* sqrt(R) delta^(3/2), at force F."""
    delta_m = (3.0 * force_N / (4.0 * modulus_Pa * math.sqrt(radius_m))) ** (2.0 / 3.0)
    return force_N / delta_m


def flat_punch_stiffness_N_per_m(radius_m: float, modulus_Pa: float) -> float:
    """Rigid flat circular punch on an elastic half-space (Boussinesq): F = 2 a E* delta, exact and linear."""
    return 2.0 * radius_m * modulus_Pa


def restitution_from_damping_ratio(zeta: float) -> float:
    """Restitution of a Kelvin-Voigt contact that opens when its force k d + c d' reaches zero.

    With zeta = c / (2 sqrt(k m)): e = exp(-zeta (pi - 2 asin zeta) / sqrt(1 - zeta^2)) for zeta < 1,
    exp(-2 zeta acosh(zeta) / sqrt(zeta^2 - 1)) for zeta > 1, exp(-2) at zeta = 1 (derivation in
    docs/lumped.md)."""
    if zeta < 0:
        raise ValueError("damping ratio must be >= 0")
    if zeta == 0:
        return 1.0
    if abs(zeta - 1.0) < 1e-9:
        return math.exp(-2.0)
    if zeta < 1.0:
        return math.exp(-zeta * (math.pi - 2.0 * math.asin(zeta)) / math.sqrt(1.0 - zeta * zeta))
    return math.exp(-2.0 * zeta * math.acosh(zeta) / math.sqrt(zeta * zeta - 1.0))


def contact_duration_s(stiffness_N_per_m: float, damping_N_s_per_m: float, mass_kg: float) -> float:
    """Duration of one impact of mass m on a Kelvin-Voigt layer (no gravity) until the force is zero."""
    omega_n = math.sqrt(stiffness_N_per_m / mass_kg)
    zeta = damping_N_s_per_m / (2.0 * math.sqrt(stiffness_N_per_m * mass_kg))
    if zeta == 0:
        return math.pi / omega_n
    if abs(zeta - 1.0) < 1e-9:
        return 2.0 / omega_n
    if zeta < 1.0:
        return (math.pi - 2.0 * math.asin(zeta)) / (omega_n * math.sqrt(1.0 - zeta * zeta))
    return 2.0 * math.acosh(zeta) / (omega_n * math.sqrt(zeta * zeta - 1.0))


def damping_ratio_from_restitution(restitution: float) -> float:
    """Inverse of restitution_from_damping_ratio (monotone decreasing in zeta)."""
    if not 0.0 < restitution <= 1.0:
        raise ValueError("restitution must be in (0, 1]")
    if restitution == 1.0:
        return 0.0
    upper = 1.0
    while restitution_from_damping_ratio(upper) > restitution:
        upper *= 2.0
    return brentq(
        lambda z: restitution_from_damping_ratio(z) - restitution, 0.0, upper, xtol=1e-15, rtol=1e-15
    )


@dataclass(frozen=True)
class ContactParameters:
    stiffness_N_per_m: float
    damping_N_s_per_m: float
    reduced_mass_kg: float
    damping_ratio: float
    restitution: float
    contact_duration_s: float


@dataclass(frozen=True)
class LumpedParameters:
    """SI numbers of eqs. 5-16 (after every rule and default has been applied)."""

    modal_mass_kg: float
    modal_stiffness_N_per_m: float
    modal_damping_N_s_per_m: float
    force_factor_N_per_V: float
    clamped_capacitance_F: float
    transducer_mass_kg: float
    free_mass_kg: float
    stem_mass_kg: float
    gravity_m_per_s2: float
    downforce_N: float
    drive_angular_frequency_rad_per_s: float
    voltage_amplitude_V: float
    contacts: tuple[ContactParameters, ContactParameters, ContactParameters]

    @property
    def drive_frequency_Hz(self) -> float:
        return self.drive_angular_frequency_rad_per_s / (2.0 * math.pi)

    @property
    def resonance_angular_frequency_rad_per_s(self) -> float:
        return math.sqrt(self.modal_stiffness_N_per_m / self.modal_mass_kg)

    def free_tip_amplitude_m(self) -> float:
        """Amplitude of x for the free transducer at the drive frequency (1-DOF response)."""
        omega = self.drive_angular_frequency_rad_per_s
        return (
            self.force_factor_N_per_V
            * self.voltage_amplitude_V
            / abs(
                complex(
                    self.modal_stiffness_N_per_m - self.modal_mass_kg * omega**2,
                    self.modal_damping_N_s_per_m * omega,
                )
            )
        )

    def to_report(self) -> dict:
        out = asdict(self)
        out["contacts"] = {name: asdict(c) for name, c in zip(CONTACT_NAMES, self.contacts)}
        out["drive_frequency_Hz"] = self.drive_frequency_Hz
        out["resonance_frequency_Hz"] = self.resonance_angular_frequency_rad_per_s / (2 * math.pi)
        out["free_tip_amplitude_m"] = self.free_tip_amplitude_m()
        return out


def contact_stiffness_N_per_m(contact: ContactSection) -> float:
    if contact.stiffness_rule == "given":
        return float(contact.stiffness_N_per_m)
    modulus = effective_modulus_Pa(
        contact.youngs_modulus_upper_Pa,
        contact.poisson_upper,
        contact.youngs_modulus_lower_Pa,
        contact.poisson_lower,
    )
    if contact.stiffness_rule == "hertz_secant":
        return hertz_secant_stiffness_N_per_m(contact.radius_m, modulus, contact.reference_force_N)
    return flat_punch_stiffness_N_per_m(contact.radius_m, modulus)


def _contact_parameters(contact: ContactSection, reduced_mass_kg: float) -> ContactParameters:
    stiffness = contact_stiffness_N_per_m(contact)
    critical = 2.0 * math.sqrt(stiffness * reduced_mass_kg)
    if contact.damping_N_s_per_m is not None:
        damping = float(contact.damping_N_s_per_m)
        zeta = damping / critical
    else:
        zeta = damping_ratio_from_restitution(contact.restitution)
        damping = zeta * critical
    return ContactParameters(
        stiffness_N_per_m=stiffness,
        damping_N_s_per_m=damping,
        reduced_mass_kg=reduced_mass_kg,
        damping_ratio=zeta,
        restitution=restitution_from_damping_ratio(zeta),
        contact_duration_s=contact_duration_s(stiffness, damping, reduced_mass_kg),
    )


def derive_parameters(section: LumpedSection) -> LumpedParameters:
    """Apply the rules of docs/lumped.md to a validated section."""
    trans = section.transducer
    if section.source == "circuit":
        circuit = load_circuit(section.circuit_file, None, "lumped.circuit_file")
        modal_mass = circuit["modal_mass_kg"]
        modal_stiffness = circuit["modal_stiffness_N_per_m"]
        modal_damping = circuit["modal_damping_N_s_per_m"]
        force_factor = circuit["force_factor_N_per_V"]
        capacitance = circuit["clamped_capacitance_F"]
    else:
        modal_mass = trans.modal_mass_kg
        omega_r = 2.0 * math.pi * trans.resonance_frequency_Hz
        modal_stiffness = modal_mass * omega_r**2
        modal_damping = modal_mass * omega_r / trans.quality_factor
        force_factor = trans.force_factor_N_per_V
        capacitance = trans.clamped_capacitance_F

    fm = section.free_mass
    free_mass = (
        fm.mass_kg if fm.mass_kg is not None else fm.density_kg_per_m3 * math.pi * fm.diameter_m**3 / 6.0
    )
    stem_mass = section.stem.mass_kg
    transducer_mass = trans.total_mass_kg

    drive = section.drive
    if drive.frequency_mode == "resonance":
        omega = math.sqrt(modal_stiffness / modal_mass)
    else:
        omega = 2.0 * math.pi * drive.frequency_Hz
    if drive.voltage_amplitude_V is not None:
        voltage = drive.voltage_amplitude_V
    else:
        amplitude = DEFAULT_TIP_AMPLITUDE_m if drive.tip_amplitude_m is None else drive.tip_amplitude_m
        receptance = abs(complex(modal_stiffness - modal_mass * omega**2, modal_damping * omega))
        voltage = amplitude * receptance / force_factor

    # The tip meets a ball with the rigid mass and the modal mass in series (a tip force drives both
    # modes), so its impact mass is m_t m_m / (m_t + m_m).
    tip_mass = transducer_mass * modal_mass / (transducer_mass + modal_mass)
    reduced = (
        tip_mass * free_mass / (tip_mass + free_mass),
        free_mass * stem_mass / (free_mass + stem_mass),
        stem_mass,  # the rock layer is massless
    )
    contacts = tuple(
        _contact_parameters(c, m)
        for c, m in zip(
            (section.contact_tip_ball, section.contact_ball_stem, section.contact_stem_rock), reduced
        )
    )
    return LumpedParameters(
        modal_mass_kg=modal_mass,
        modal_stiffness_N_per_m=modal_stiffness,
        modal_damping_N_s_per_m=modal_damping,
        force_factor_N_per_V=force_factor,
        clamped_capacitance_F=capacitance,
        transducer_mass_kg=transducer_mass,
        free_mass_kg=free_mass,
        stem_mass_kg=stem_mass,
        gravity_m_per_s2=section.gravity_m_per_s2,
        downforce_N=section.downforce_N,
        drive_angular_frequency_rad_per_s=omega,
        voltage_amplitude_V=voltage,
        contacts=contacts,
    )
