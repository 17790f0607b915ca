"""The drive-amplitude rule, once for every tier: which voltage each driven electrode gets.

The nominal amplitude of a driven electrode (kind 'voltage') is its ``amplitude_V``, else
``transient.drive.voltage_V``; its phase its ``phase_deg``. The run's drive amplitude is the largest nominal
one and each electrode carries its share of it (weight in (0, 1]); all nominal amplitudes 0 (a case driven to a
target tip amplitude) weigh 1. A target ``transient.drive.tip_amplitude_m`` scales every electrode together:
drive amplitude = target / |steady amplitude at the drive point per volt of drive amplitude| (a harmonic
solve of the tier's own model). The time function: U_e(t) = A_e sin(wt + phase_e) from rest, A_e cos(wt +
phase_e) after a harmonic start.

A drive locked to the model's resonance (``transient.drive.lock = "resonance"``) runs at the tier's own model's
resonance nearest ``frequency_Hz`` plus ``detuning_Hz`` (:func:`locked_case`): the frequency a phase-locked driver
holds, so the drive sits where the paper's does relative to the mode whichever mesh computes it.
"""

from __future__ import annotations

import math

import numpy as np


def drive_weights(case) -> tuple[float, dict[str, float]]:
    """(largest nominal electrode amplitude [V], weight of each driven electrode)."""
    voltage = case.transient.drive.voltage_V
    nominal = {n: (e.amplitude_V if e.amplitude_V is not None else voltage)
               for n, e in case.electrodes.items() if e.kind == "voltage"}
    largest = max(nominal.values(), default=0.0)
    if largest <= 0.0:
        return 0.0, {n: 1.0 for n in nominal}
    return largest, {n: a / largest for n, a in nominal.items()}


def is_driven(case) -> bool:
    """Whether the transient has a time-harmonic excitation at ``transient.drive.frequency_Hz``: a driven
    electrode with a nonzero amplitude, a target tip amplitude, or a base motion (the field frames lock to its
    phase only then: app/transient/fields.py frame_schedule)."""
    cfg = case.transient
    largest, _ = drive_weights(case)
    return largest > 0 or cfg.drive.tip_amplitude_m is not None or bool(cfg.base_motions)


def electrode_amplitudes(case, names: list[str]) -> tuple[float, np.ndarray, np.ndarray]:
    """(drive amplitude [V] before a target scales it, weights and phases [rad] of the electrodes ``names``)."""
    largest, weights = drive_weights(case)
    return (largest, np.array([weights[n] for n in names], dtype=float),
            np.array([math.radians(case.electrodes[n].phase_deg) for n in names], dtype=float))


def target_voltage(target_m: float, amplitude_per_volt_m: float) -> float:
    """The drive amplitude [V] that gives the target steady amplitude at the drive point."""
    if not amplitude_per_volt_m > 0:
        from app.errors import NumericalFailure

        raise NumericalFailure("the drive does not move the drive point (harmonic solve): no voltage reaches the "
                               "target amplitude")
    return target_m / amplitude_per_volt_m


def locked_case(case, resonances_Hz) -> tuple[object, dict]:
    """(the case with its drive frequency locked to the resonance, the summary's record of it), for a case with
    ``transient.drive.lock = "resonance"``; ``resonances_Hz``: the tier's model's ``lock_modes`` natural frequencies
    nearest the case's ``frequency_Hz`` (electrodes short-circuited). The drive runs at their mean plus
    ``detuning_Hz``. What the case's frequency also sets stays at its value as written (the nominal): the reduced
    basis's cutoff and enrichment target and the damping's reference frequency, so locking the drive neither moves
    them nor changes the reduced model's cache key."""
    import dataclasses

    drive = case.transient.drive
    nominal = drive.frequency_Hz
    resonances = np.sort(np.asarray(resonances_Hz, dtype=float))
    resonance = float(np.mean(resonances))
    frequency = resonance + drive.detuning_Hz
    changes = {"transient": dataclasses.replace(
        case.transient, drive=dataclasses.replace(drive, frequency_Hz=frequency))}
    red = getattr(case, "reduction", None)
    if red is not None:
        cutoff = red.cutoff_Hz
        if cutoff is None and red.n_modes is None:
            cutoff = red.cutoff_factor * nominal
        changes["reduction"] = dataclasses.replace(red, cutoff_Hz=cutoff, enrich_near_Hz=red.enrich_near_Hz or nominal)
    if case.damping is not None:
        changes["damping"] = dataclasses.replace(
            case.damping, reference_frequency_Hz=case.damping.reference_frequency_Hz or nominal)
    record = {"lock": "resonance", "nominal_frequency_Hz": nominal, "resonances_Hz": resonances.tolist(),
              "resonance_Hz": resonance, "detuning_Hz": float(drive.detuning_Hz), "frequency_Hz": frequency,
              "detuning_relative": float(drive.detuning_Hz) / resonance}
    return dataclasses.replace(case, **changes), record


def drive_lock_line(record: dict) -> str:
    """The log line of a drive locked to the resonance (both tiers)."""
    pair = ", ".join(f"{f:.2f}" for f in record["resonances_Hz"])
    return (f"drive locked to the model's resonance: {record['resonance_Hz']:.2f} Hz (mean of {pair} Hz, sought near "
            f"{record['nominal_frequency_Hz']:.2f} Hz) {record['detuning_Hz']:+.2f} Hz -> drive "
            f"{record['frequency_Hz']:.2f} Hz")
