"""1-DOF equivalent model of the working mode (drill paper Fig. 10), referred to a named point.

    m_m x'' + c_m x' + k_m x = alpha U      (mechanical branch)
    Q = alpha x + C_p U                     (electrical port)

With the mass-normalised short-circuit mode psi (psi^T M psi = 1) and psi_P its displacement at the
point: m_m = 1/psi_P^2, k_m = omega_r^2 m_m, c_m = (psi^T C psi) m_m, and the force factor
alpha = theta / psi_P with theta = psi^T f_1V the modal force of a 1 V drive, which equals the
charge the mode induces on the shorted driven electrodes (theta = -chi^T K psi). The clamped
capacitance follows from the open-circuit frequency: omega_a^2 = omega_r^2 + alpha^2 / (m_m C_p).
"""

from __future__ import annotations

import math

import numpy as np

from app.fe.model import FEModel
from app.fe.operators import Operators, charge, indicator
from app.harmonic import HarmonicResult
from app.modal import ModalResult


def equivalent_circuit(model: FEModel, ops: Operators, modal: ModalResult, harmonic: HarmonicResult | None,
                       point: str) -> dict:
    mode = modal.working_mode
    psi_p = model.point_values(mode.vector)[point]
    omega_r = 2 * math.pi * mode.frequency_Hz
    m_m = 1.0 / psi_p**2
    k_m = omega_r**2 * m_m
    c_m = 0.0
    if ops.C is not None:
        Cpsi = ops.C.createVecLeft()
        ops.C.mult(mode.vector, Cpsi)
        c_m = Cpsi.dot(mode.vector) * m_m
        Cpsi.destroy()
    chi = indicator(model, model.electrodes_of("voltage"))
    theta = charge(ops.K, mode.vector, chi)
    chi.destroy()
    alpha = abs(theta / psi_p)
    out = {
        "point": point,
        "resonance_Hz": mode.frequency_Hz,
        "modal_mass_kg": m_m,
        "modal_stiffness_N_per_m": k_m,
        "modal_damping_N_s_per_m": c_m,
        "force_factor_N_per_V": alpha,
    }
    f_a = modal.antiresonance_Hz()
    if f_a is not None and f_a > mode.frequency_Hz:
        omega_a = 2 * math.pi * f_a
        c_p = alpha**2 / (m_m * (omega_a**2 - omega_r**2))
        out["antiresonance_Hz"] = f_a
        out["clamped_capacitance_F"] = c_p
    if c_m > 0:
        out["mechanical_quality_factor"] = omega_r * m_m / c_m
    if harmonic is not None and harmonic.peak is not None and "clamped_capacitance_F" in out:
        f = harmonic.peak.frequency_Hz
        y_model = bvd_admittance(out, f)
        out["admittance_at_peak_fe_S"] = abs(harmonic.peak.admittance_S)
        out["admittance_at_peak_circuit_S"] = abs(y_model)
        amp_fe = abs(harmonic.peak.displacement_m[point]) / model.case.harmonic.voltage_V
        amp_model = abs(bvd_displacement_per_volt(out, f))
        out["displacement_per_volt_at_peak_fe_m_per_V"] = amp_fe
        out["displacement_per_volt_at_peak_circuit_m_per_V"] = amp_model
    return out


def bvd_displacement_per_volt(circuit: dict, frequency_Hz) -> complex:
    omega = 2 * np.pi * np.asarray(frequency_Hz)
    z = circuit["modal_stiffness_N_per_m"] - omega**2 * circuit["modal_mass_kg"] + 1j * omega * circuit[
        "modal_damping_N_s_per_m"]
    return circuit["force_factor_N_per_V"] / z


def bvd_admittance(circuit: dict, frequency_Hz) -> complex:
    """Y = i omega (C_p + alpha^2 / (k_m - omega^2 m_m + i omega c_m))."""
    omega = 2 * np.pi * np.asarray(frequency_Hz)
    x_per_v = bvd_displacement_per_volt(circuit, frequency_Hz)
    return 1j * omega * (circuit["clamped_capacitance_F"] + circuit["force_factor_N_per_V"] * x_per_v)
