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
