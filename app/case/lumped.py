"""The ``[lumped]`` table of a case file: typed, bounded, with SI units in every name.

Every default is the drill paper's scene (8 mm steel ball, ~300 g transducer at 20.1 kHz,
15 um free tip amplitude); ``docs/lumped.md`` justifies each number.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from app.case.validate import param
from app.errors import CaseError

CIRCUIT_KEYS = (
    "modal_mass_kg",
    "modal_stiffness_N_per_m",
    "modal_damping_N_s_per_m",
    "force_factor_N_per_V",
    "clamped_capacitance_F",
)


@dataclass(frozen=True)
class TransducerSection:
    total_mass_kg: float = param(0.300, gt=0, unit="kg", doc="rigid-body mass m_t (system II)")
    modal_mass_kg: float = param(0.050, gt=0, unit="kg", doc="modal mass m_m at the tip (system I)")
    resonance_frequency_Hz: float = param(20100.0, gt=0, unit="Hz", doc="sets k_m = m_m (2 pi f)^2")
    quality_factor: float = param(400.0, gt=0, unit="", doc="mechanical Q; c_m = m_m omega / Q")
    force_factor_N_per_V: float = param(1.0, gt=0, unit="N/V", doc="electromechanical force factor alpha")
    clamped_capacitance_F: float = param(8e-9, gt=0, unit="F", doc="C_p; reported, not in the mechanics")


@dataclass(frozen=True)
class DriveSection:
    frequency_mode: Literal["resonance", "fixed"] = param(
        "resonance",
        doc="'resonance' drives at sqrt(k_m/m_m) (what a PLL locks to); 'fixed' uses frequency_Hz",
    )
    frequency_Hz: float = param(20100.0, gt=0, unit="Hz", doc="drive frequency when frequency_mode='fixed'")
    tip_amplitude_m: float | None = param(
        None,
        ge=0,
        unit="m",
        doc="free tip amplitude; sets the voltage (default 15e-6 if no voltage is given)",
    )
    voltage_amplitude_V: float | None = param(None, ge=0, unit="V", doc="drive voltage amplitude")

    def check(self, file, prefix):
        if self.tip_amplitude_m is not None and self.voltage_amplitude_V is not None:
            raise CaseError(
                file,
                f"{prefix}.voltage_amplitude_V",
                "give either tip_amplitude_m or voltage_amplitude_V, not both",
            )


@dataclass(frozen=True)
class FreeMassSection:
    diameter_m: float = param(8e-3, gt=0, unit="m", doc="steel ball diameter")
    density_kg_per_m3: float = param(7850.0, gt=0, unit="kg/m^3", doc="ball density")
    mass_kg: float | None = param(None, gt=0, unit="kg", doc="overrides the mass from diameter and density")


@dataclass(frozen=True)
class StemSection:
    mass_kg: float = param(0.040, gt=0, unit="kg", doc="drill stem mass m_d (system IV)")


@dataclass(frozen=True)
class ContactSection:
    stiffness_rule: Literal["given", "hertz_secant", "flat_punch"] = param(
        "hertz_secant", doc="how the linear contact stiffness is found"
    )
    stiffness_N_per_m: float | None = param(None, gt=0, unit="N/m", doc="used when stiffness_rule='given'")
    radius_m: float = param(
        4e-3, gt=0, unit="m", doc="sphere radius (hertz_secant) or punch radius (flat_punch)"
    )
    youngs_modulus_upper_Pa: float = param(210e9, gt=0, unit="Pa", doc="upper body")
    poisson_upper: float = param(0.30, ge=0, lt=0.5, doc="upper body")
    youngs_modulus_lower_Pa: float = param(210e9, gt=0, unit="Pa", doc="lower body")
    poisson_lower: float = param(0.30, ge=0, lt=0.5, doc="lower body")
    reference_force_N: float = param(300.0, gt=0, unit="N", doc="force at which the Hertz secant is taken")
    damping_N_s_per_m: float | None = param(
        None, unit="N s/m", doc="Kelvin-Voigt damper; overrides restitution"
    )
    restitution: float = param(
        0.8, gt=0, le=1, doc="coefficient of restitution under the force-zero opening rule"
    )

    def check(self, file, prefix):
        if self.stiffness_rule == "given" and self.stiffness_N_per_m is None:
            raise CaseError(file, f"{prefix}.stiffness_N_per_m", "required when stiffness_rule = 'given'")
        if self.stiffness_rule != "given" and self.stiffness_N_per_m is not None:
            raise CaseError(
                file,
                f"{prefix}.stiffness_N_per_m",
                f"set stiffness_rule = 'given' to use it (rule is {self.stiffness_rule!r})",
            )
        if self.damping_N_s_per_m is not None and self.damping_N_s_per_m < 0:
            # A negative damper adds a pulling (tensile) force while the bodies approach, and the
            # force-zero opening rule cannot stop that: reject it.
            raise CaseError(
                file,
                f"{prefix}.damping_N_s_per_m",
                "must be >= 0 N s/m (a negative damper makes the contact pull), "
                f"got {self.damping_N_s_per_m}",
            )
        if self.damping_N_s_per_m is not None and not math.isfinite(self.damping_N_s_per_m):
            raise CaseError(file, f"{prefix}.damping_N_s_per_m", "must be finite")


def _contact_tip_ball() -> ContactSection:
    return ContactSection()


def _contact_ball_stem() -> ContactSection:
    return ContactSection()


def _contact_stem_rock() -> ContactSection:
    return ContactSection(
        stiffness_rule="flat_punch",
        radius_m=3e-3,
        youngs_modulus_lower_Pa=50e9,
        poisson_lower=0.25,
        restitution=0.5,
    )


@dataclass(frozen=True)
class InitialSection:
    vibration: Literal["steady_state", "rest"] = param(
        "steady_state", doc="start the modal coordinate at the free harmonic steady state, or at rest"
    )
    transducer_z_m: float = param(150e-6, unit="m", doc="rigid transducer coordinate z (tip = x + z)")
    free_mass_w_m: float = param(100e-6, unit="m", doc="free-mass coordinate w")
    stem_v_m: float = param(50e-6, unit="m", doc="stem coordinate v (0 = resting on unloaded rock)")
    transducer_velocity_m_per_s: float = param(0.0, unit="m/s")
    free_mass_velocity_m_per_s: float = param(0.0, unit="m/s")
    stem_velocity_m_per_s: float = param(0.0, unit="m/s")


@dataclass(frozen=True)
class SolverSection:
    samples_per_period: int = param(
        16, ge=6, doc="sampling steps per shortest period of any contact state (event detection)"
    )
    zeno_window_s: float = param(
        1e-9, gt=0, unit="s", doc="two switches closer than this count as chattering"
    )
    zeno_max_switches: int = param(4, ge=2, doc="rapid switches before a contact is held closed for a window")


@dataclass(frozen=True)
class LumpedOutputSection:
    output_interval_s: float = param(1e-5, gt=0, unit="s", doc="time-series sample interval")
    write_time_series: bool = param(
        True, doc="keep the time series transient.h5 and draw its plots (false: the run writes it while it "
                  "needs it, for --resume and the statistics, and removes it at the end)")
    checkpoint_interval_steps: int = param(
        5000, ge=0, doc="checkpoint (for `piezodyn run --resume DIR`) every N output intervals (time-series "
                        "rows) and at the end; 0: end only")
    plots: bool = param(True, doc="write PNG plots (Fig. 12 and Fig. 5 style)")
    min_flight_rise_m: float = param(
        50e-6,
        ge=0,
        unit="m",
        doc="a tip/free-mass open interval is a flight if z rises at least this much above take-off",
    )
    histogram_bins: int = param(20, ge=1, doc="bins of the flight-duration histogram")
    bodies_interval_s: float | None = param(
        None, gt=0, unit="s", doc="write the transducer tip, ball, stem and rock drawn with shapes, moving with their "
                                  "coordinates, as transient_bodies.xdmf (ParaView, meshio) at t = 0 and at the first "
                                  "sample at or after every multiple of this; at least output_interval_s; unset: "
                                  "none (docs/lumped.md)")


@dataclass(frozen=True)
class LumpedSection:
    model: Literal["impact_chain"] = param(
        "impact_chain", doc="the lumped model: 'impact_chain' (this table: transducer, free mass, stem, rock; the "
                            "drill paper's eqs. 5-16) or 'friction_drive' (the travelling-wave motor, "
                            "[lumped] with model = \"friction_drive\")")
    source: Literal["typed", "circuit"] = param(
        "typed", doc="transducer parameters typed or from an FE circuit"
    )
    circuit_file: str | None = param(None, doc="JSON with the equivalent circuit (flat or summary.json)")
    duration_s: float = param(0.2, gt=0, unit="s", doc="simulated time window")
    downforce_N: float = param(0.0, ge=0, unit="N", doc="additional downforce F_a on the transducer")
    gravity_m_per_s2: float = param(9.81, ge=0, unit="m/s^2", doc="on systems II-IV, not on I")
    transducer: TransducerSection = field(default_factory=TransducerSection)
    drive: DriveSection = field(default_factory=DriveSection)
    free_mass: FreeMassSection = field(default_factory=FreeMassSection)
    stem: StemSection = field(default_factory=StemSection)
    contact_tip_ball: ContactSection = field(default_factory=_contact_tip_ball)
    contact_ball_stem: ContactSection = field(default_factory=_contact_ball_stem)
    contact_stem_rock: ContactSection = field(default_factory=_contact_stem_rock)
    initial: InitialSection = field(default_factory=InitialSection)
    solver: SolverSection = field(default_factory=SolverSection)
    output: LumpedOutputSection = field(default_factory=LumpedOutputSection)

    def check(self, file, prefix):
        dotted = f"{prefix}." if prefix else ""
        if self.output.output_interval_s > self.duration_s:
            raise CaseError(
                file,
                f"{dotted}output.output_interval_s",
                f"must not exceed duration_s = {self.duration_s} s, got {self.output.output_interval_s} s",
            )
        bodies_s = self.output.bodies_interval_s
        if bodies_s is not None and not self.output.output_interval_s * (1 - 1e-12) <= bodies_s <= self.duration_s:
            raise CaseError(file, f"{dotted}output.bodies_interval_s",
                            f"must lie between output_interval_s = {self.output.output_interval_s} s and duration_s = "
                            f"{self.duration_s} s, got {bodies_s} s")
        if self.source == "circuit":
            if not self.circuit_file:
                raise CaseError(file, f"{dotted}circuit_file", "required when source = 'circuit'")
            path = Path(self.circuit_file)
            if not path.is_absolute() and file and not path.exists():
                path = Path(file).parent / path
            load_circuit(path, file, f"{dotted}circuit_file")
            # Store the resolved path so the run does not depend on the working directory.
            object.__setattr__(self, "circuit_file", str(path.resolve()))


def load_circuit(path: str | Path, file: str | None = None, key: str | None = "circuit_file") -> dict:
    """Read an equivalent circuit: a flat JSON with CIRCUIT_KEYS, or a summary.json holding them
    under ``results.circuit``. Missing file, missing key or a non-positive value -> CaseError."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CaseError(file, key, f"cannot read circuit file {str(path)!r} ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise CaseError(file, key, f"circuit file {str(path)!r} is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise CaseError(file, key, f"circuit file {str(path)!r} is not JSON: {exc}") from None
    if isinstance(data, dict) and isinstance(data.get("results"), dict) and "circuit" in data["results"]:
        data = data["results"]["circuit"]
    if not isinstance(data, dict):
        raise CaseError(file, key, f"circuit file {str(path)!r} holds no circuit table")
    circuit = {}
    for name in CIRCUIT_KEYS:
        value = data.get(name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(file, key, f"circuit file {str(path)!r}: {name} missing or not a number")
        if not math.isfinite(value) or value <= 0:
            raise CaseError(file, key, f"circuit file {str(path)!r}: {name} must be > 0, got {value}")
        circuit[name] = float(value)
    return circuit


# ----------------------------------------------------------------------------------------------------------------
# model = "friction_drive": a travelling-wave motor as the stator's wave mode, a rigid rotor and the rigid-Winkler
# friction-drive law (docs/lumped-motor.md). Every default is the stator and rotor of the motor case's pinned
# stator (bench/cases/wwusm-motor-pinned.toml): its F(1,4) pair referred to the contact circle, taken from the
# modal tier's reduced stator by bench/motor_lumped_parameters.py.

MODAL_SUMMARY_KEYS = ("modal_force_per_volt_N_per_V", "modal_stiffness_N_per_m", "damping_ratio")


@dataclass(frozen=True)
class WaveModeSection:
    """The stator's wave mode (a degenerate pair of order n) referred to the normal amplitude W of the wave at
    the contact circle (app/modal.py:contact_force reports the same quantities)."""

    source: Literal["typed", "modal_summary"] = param(
        "typed", doc="'typed': the keys below; 'modal_summary': resonance, stiffness, damping and force per volt "
                     "from a stator modal run's summary.json (results.modal.contact_force), the tangential ratio "
                     "typed")
    modal_summary_file: str | None = param(
        None, doc="summary.json of a modal run with [modal.contact_force] (a relative path: from the case file)")
    resonance_frequency_Hz: float = param(35992.42, gt=0, unit="Hz", doc="the pair's centre, short circuit")
    modal_stiffness_N_per_m: float = param(8.6962e7, gt=0, unit="N/m", doc="k_m referred to W (m_m = k_m / omega_m^2)")
    damping_ratio: float = param(0.0019341, gt=0, lt=1, unit="", doc="zeta of the mode (c_m = 2 zeta k_m / omega_m)")
    force_per_volt_N_per_V: float = param(
        0.018114, gt=0, unit="N/V", doc="modal force F_m per volt of drive amplitude, referred to W: at resonance "
                                        "W = F_m / (2 zeta k_m)")
    tangential_ratio: float = param(
        0.2994, gt=0, unit="", doc="U_t / W: the surface's circumferential amplitude over its normal amplitude at "
                                   "the contact circle, in the mode")

    def check(self, file, prefix):
        if self.source == "modal_summary":
            if not self.modal_summary_file:
                raise CaseError(file, f"{prefix}.modal_summary_file", "required when source = 'modal_summary'")
            path = Path(self.modal_summary_file)
            if not path.is_absolute() and file and not path.exists():
                path = Path(file).parent / path
            load_modal_summary(path, file, f"{prefix}.modal_summary_file")
            object.__setattr__(self, "modal_summary_file", str(path.resolve()))
        elif self.modal_summary_file is not None:
            raise CaseError(file, f"{prefix}.modal_summary_file", "is read only with source = 'modal_summary'")


def load_modal_summary(path: str | Path, file: str | None = None, key: str | None = None) -> dict:
    """The wave mode of a stator modal run's summary.json: {resonance_frequency_Hz, modal_stiffness_N_per_m,
    damping_ratio, force_per_volt_N_per_V} from results.modal.contact_force (the pair's mean frequency). Missing
    file or key, or a non-positive value -> CaseError naming ``key``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CaseError(file, key, f"cannot read {str(path)!r} ({exc.strerror})") from None
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise CaseError(file, key, f"{str(path)!r} is not a JSON summary") from None
    cf = ((data.get("results") or {}).get("modal") or {}).get("contact_force") if isinstance(data, dict) else None
    if not isinstance(cf, dict):
        raise CaseError(file, key, f"{str(path)!r} has no results.modal.contact_force (run the stator's modal "
                                   "analysis with [modal.contact_force])")
    out = {}
    for name in MODAL_SUMMARY_KEYS:
        value = cf.get(name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise CaseError(file, key, f"{str(path)!r}: contact_force.{name} missing or not a number > 0")
        out[name] = float(value)
    modes = cf.get("modes") or []
    freqs = [m.get("frequency_Hz") for m in modes if isinstance(m, dict)]
    if not freqs or not all(isinstance(f, (int, float)) and f > 0 for f in freqs):
        raise CaseError(file, key, f"{str(path)!r}: contact_force.modes[*].frequency_Hz missing")
    return {"resonance_frequency_Hz": float(sum(freqs) / len(freqs)),
            "modal_stiffness_N_per_m": out["modal_stiffness_N_per_m"], "damping_ratio": out["damping_ratio"],
            "force_per_volt_N_per_V": out["modal_force_per_volt_N_per_V"]}


@dataclass(frozen=True)
class MotorDriveSection:
    voltage_amplitude_V: float = param(200.0, gt=0, unit="V", doc="amplitude of each phase (400 Vpp: 200 V)")
    frequency_Hz: float = param(36065.0, gt=0, unit="Hz", doc="drive frequency")


@dataclass(frozen=True)
class MotorRotorSection:
    preload_N: float = param(0.98, gt=0, unit="N", doc="axial preload P (N = P / sin(half_angle) on the cone)")
    load_torque_N_m: float = param(0.0, ge=0, unit="N m", doc="the operating point's load torque (opposing the "
                                                                 "drive)")
    inertia_kg_m2: float = param(1.52e-6, gt=0, unit="kg m^2", doc="spin inertia: sets only the start-up time "
                                                                   "constant I Omega_0 / T_stall (reported)")


@dataclass(frozen=True)
class MotorContactSection:
    radius_m: float = param(0.012862384017536786, gt=0, unit="m", doc="contact circle r_c")
    half_angle_deg: float = param(15.0, gt=0, lt=90, unit="deg", doc="cone half-angle of the contact face")
    width_m: float = param(3.1051e-4, gt=0, unit="m", doc="contact width b across the band (band area / 2 pi r_c)")
    stiffness_Pa_per_m: float = param(4e13, gt=0, unit="Pa/m", doc="Winkler (penalty) stiffness k_w per area")
    mu_dynamic: float = param(0.57, ge=0, unit="", doc="Coulomb coefficient (MU)")
    static_ratio: float = param(1.298, ge=1, unit="", doc="mu_s / mu_d (FACT); without decay mu_s acts at every "
                                                          "slip speed, as in the FE and modal tiers")

    def check(self, file, prefix):
        if self.mu_dynamic <= 0:
            raise CaseError(file, f"{prefix}.mu_dynamic", "must be > 0: a friction drive needs friction")


@dataclass(frozen=True)
class FrictionDriveSection:
    """``[lumped]`` with ``model = "friction_drive"``: the travelling-wave motor's steady operating point and
    speed-torque curve from the stator's wave mode and the rigid-Winkler friction-drive law (docs/lumped-motor.md)."""

    model: Literal["friction_drive"] = param(doc="'friction_drive' (this table)")
    branch: Literal["upper", "lower"] = param(
        "upper", doc="which root of the wave's amplitude equation is the operating point: 'upper' (the largest "
                     "wave) or 'lower' (the smallest, where there are two or more); every root is reported with "
                     "its stability")
    curve_points: int = param(9, ge=2, le=200, doc="points of the speed-torque curve, no load to stall")
    stator: WaveModeSection = field(default_factory=WaveModeSection)
    drive: MotorDriveSection = field(default_factory=MotorDriveSection)
    rotor: MotorRotorSection = field(default_factory=MotorRotorSection)
    contact: MotorContactSection = field(default_factory=MotorContactSection)

    def check(self, file, prefix):
        dotted = f"{prefix}." if prefix else ""
        mu = self.contact.mu_dynamic * self.contact.static_ratio
        bound = mu * self.rotor.preload_N / math.sin(math.radians(self.contact.half_angle_deg)) * self.contact.radius_m
        if self.rotor.load_torque_N_m > bound:
            raise CaseError(file, f"{dotted}rotor.load_torque_N_m",
                            f"{self.rotor.load_torque_N_m:g} N m exceeds the stall torque mu N r_c = {bound:.4g} N m "
                            "(the rotor would turn backwards)")


LUMPED_MODELS = {"impact_chain": LumpedSection, "friction_drive": FrictionDriveSection}


def lumped_section_type(raw, file: str | None):
    """The dataclass of a ``[lumped]`` table, by its ``model`` key (default 'impact_chain')."""
    model = raw.get("model", "impact_chain") if isinstance(raw, dict) else "impact_chain"
    if model not in LUMPED_MODELS:
        raise CaseError(file, "lumped.model", f"unknown lumped model {model!r} (models: {', '.join(LUMPED_MODELS)})")
    return LUMPED_MODELS[model]
