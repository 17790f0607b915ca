"""Linear systems of eqs. 5-16 for each of the 8 contact states, and their exact propagators.

Augmented state (14 entries)::

    0 x   1 x'   2 z   3 z'   4 w   5 w'   6 v   7 v'   8 d1   9 d2   10 d3   11 one   12 sin(wt)   13 cos(wt)

x modal (vibration) coordinate, z rigid transducer coordinate (tip = x + z), w free mass, v stem,
d_i the compression of Kelvin-Voigt layer i (1 tip/ball, 2 ball/stem, 3 stem/rock). Upward is
positive and every coordinate is zero when the parts rest on each other unloaded. The constant
and the drive's sine/cosine are states, so gravity, downforce and voltage are inside the matrix
and one matrix exponential gives the exact solution over a step even when the system matrix is
singular (free flight).

Penetrations p1 = w - x - z, p2 = v - w, p3 = -v. A closed layer follows its penetration
(d_i' = p_i') and pushes with F_i = k_i d_i + c_i p_i'; an open layer relaxes, c_i d_i' + k_i d_i = 0
(eq. 16 for the rock surface s = -d3), and its gap to the approaching body is d_i - p_i.
"""

from __future__ import annotations

import math

import numpy as np

from app.lumped.linalg import mode_caches
from app.lumped.parameters import LumpedParameters

N_STATE = 14
LEVELS = 30  # dyadic refinements of the sampling step: events are located to h / 2**30
N_MODES = 8  # contact states: bit i set = contact i closed
N_LEDGER = 5  # electrical input, c_m loss, loss in layers 1..3
DIRECT_EVERY = 5  # levels whose exponential is computed directly (see Propagators)

IX, IXD, IZ, IZD, IW, IWD, IV, IVD, ID1, ID2, ID3, IONE, ISIN, ICOS = range(N_STATE)
LEDGER_NAMES = ("electrical_input", "modal_damping", "tip_ball", "ball_stem", "stem_rock")


def _row(entries: dict[int, float]) -> np.ndarray:
    row = np.zeros(N_STATE)
    for index, value in entries.items():
        row[index] += value
    return row


def penetration_rows() -> tuple[np.ndarray, np.ndarray]:
    """Rows giving p_i and p_i' from the state (shape (3, 14) each)."""
    pos = np.array([_row({IW: 1, IX: -1, IZ: -1}), _row({IV: 1, IW: -1}), _row({IV: -1})])
    vel = np.array([_row({IWD: 1, IXD: -1, IZD: -1}), _row({IVD: 1, IWD: -1}), _row({IVD: -1})])
    return pos, vel


def force_rows(p: LumpedParameters) -> np.ndarray:
    """Rows of the closed-layer forces F_i = k_i d_i + c_i p_i' (shape (3, 14))."""
    _, vel = penetration_rows()
    rows = np.zeros((3, N_STATE))
    for i, c in enumerate(p.contacts):
        rows[i] = c.damping_N_s_per_m * vel[i]
        rows[i, ID1 + i] += c.stiffness_N_per_m
    return rows


def gap_rows() -> np.ndarray:
    """Rows of d_i - p_i: the gap of an open contact (before subtracting its stored offset)."""
    pos, _ = penetration_rows()
    rows = -pos.copy()
    for i in range(3):
        rows[i, ID1 + i] += 1.0
    return rows


def system_matrix(p: LumpedParameters, mode: int) -> np.ndarray:
    """A-hat of y' = A y for contact state ``mode`` (bit i = contact i closed)."""
    a = np.zeros((N_STATE, N_STATE))
    forces = force_rows(p)
    _, vel = penetration_rows()
    closed = [(mode >> i) & 1 for i in range(3)]
    contact_force = [forces[i] if closed[i] else np.zeros(N_STATE) for i in range(3)]
    mm, mt, mf, md = p.modal_mass_kg, p.transducer_mass_kg, p.free_mass_kg, p.stem_mass_kg
    g, fa = p.gravity_m_per_s2, p.downforce_N
    alpha_u = p.force_factor_N_per_V * p.voltage_amplitude_V

    a[IX, IXD] = 1.0
    # eq. 5: m_m x'' + c_m x' + k_m x = F_c1 - F_a - alpha U
    a[IXD] = contact_force[0] / mm
    a[IXD, IX] -= p.modal_stiffness_N_per_m / mm
    a[IXD, IXD] -= p.modal_damping_N_s_per_m / mm
    a[IXD, IONE] -= fa / mm
    a[IXD, ISIN] -= alpha_u / mm
    a[IZ, IZD] = 1.0
    # eq. 6: m_t z'' = F_c1 - F_a - m_t g
    a[IZD] = contact_force[0] / mt
    a[IZD, IONE] -= fa / mt + g
    a[IW, IWD] = 1.0
    # eq. 7: m_f w'' = -F_c1 + F_c2 - m_f g
    a[IWD] = (contact_force[1] - contact_force[0]) / mf
    a[IWD, IONE] -= g
    a[IV, IVD] = 1.0
    # eq. 8: m_d v'' = -F_c2 + F_c3 - m_d g
    a[IVD] = (contact_force[2] - contact_force[1]) / md
    a[IVD, IONE] -= g
    for i, c in enumerate(p.contacts):
        if closed[i]:
            a[ID1 + i] = vel[i]
        elif c.damping_N_s_per_m > 0:
            a[ID1 + i, ID1 + i] = -c.stiffness_N_per_m / c.damping_N_s_per_m
        # an open layer without damper keeps its (zero) compression: its relaxation is instantaneous
    omega = p.drive_angular_frequency_rad_per_s
    a[ISIN, ICOS] = omega
    a[ICOS, ISIN] = -omega
    return a


def ledger_forms(p: LumpedParameters, mode: int) -> np.ndarray:
    """Symmetric Q_k with power_k = y^T Q_k y: electrical input -alpha U x', c_m x'^2 and the loss in
    each layer (c p'^2 when closed, k^2 d^2 / c while an open layer relaxes). Shape (5, 14, 14)."""
    q = np.zeros((N_LEDGER, N_STATE, N_STATE))
    alpha_u = p.force_factor_N_per_V * p.voltage_amplitude_V
    q[0, IXD, ISIN] = q[0, ISIN, IXD] = -0.5 * alpha_u
    q[1, IXD, IXD] = p.modal_damping_N_s_per_m
    _, vel = penetration_rows()
    for i, c in enumerate(p.contacts):
        if (mode >> i) & 1:
            q[2 + i] = c.damping_N_s_per_m * np.outer(vel[i], vel[i])
        elif c.damping_N_s_per_m > 0:
            q[2 + i, ID1 + i, ID1 + i] = c.stiffness_N_per_m**2 / c.damping_N_s_per_m
    return q


def shortest_period_s(p: LumpedParameters) -> float:
    """Shortest oscillation period of any contact state and of the drive."""
    omega_max = p.drive_angular_frequency_rad_per_s
    for mode in range(N_MODES):
        eig = np.linalg.eigvals(system_matrix(p, mode)[:IONE, :IONE])
        omega_max = max(omega_max, float(np.max(np.abs(eig.imag))))
    return 2.0 * math.pi / omega_max


def balancing_scales(p: LumpedParameters) -> np.ndarray:
    """State scales D (positions 1/omega, velocities 1) so that D^-1 A D has entries ~ omega:
    the matrix functions then need no more than a few squarings."""
    d = np.ones(N_STATE)
    for index in (IX, IZ, IW, IV, ID1, ID1 + 1, ID1 + 2):
        d[index] = 1.0 / p.drive_angular_frequency_rad_per_s
    return d


class Propagators:
    """Per contact state and dyadic level j (step h / 2**j): expm, ledger Gramians, impulse rows.

    Level 0 is the sampling step. Built once per parameter set (~15 ms) by the numba routines of
    ``app.lumped.linalg``, so the numbers do not depend on the BLAS thread count."""

    def __init__(self, p: LumpedParameters, step_s: float):
        self.step_s = step_s
        self.expm = np.zeros((N_MODES, LEVELS + 1, N_STATE, N_STATE))
        self.ledger = np.zeros((N_MODES, LEVELS + 1, N_LEDGER, N_STATE, N_STATE))
        self.impulse = np.zeros((N_MODES, LEVELS + 1, 3, N_STATE))
        self.event_value = np.zeros((N_MODES, 3, N_STATE))
        self.event_slope = np.zeros((N_MODES, 3, N_STATE))
        forces = force_rows(p)
        gaps = gap_rows()
        d = balancing_scales(p)
        similar = np.outer(d, 1.0 / d)  # A = D B D^-1 elementwise
        inverse_both = np.outer(1.0 / d, 1.0 / d)
        for mode in range(N_MODES):
            a = system_matrix(p, mode)
            b = a / similar
            q = ledger_forms(p, mode) * np.outer(d, d)[None, :, :]
            ex, gram, phi = mode_caches(b, q, step_s, LEVELS, DIRECT_EVERY)
            self.expm[mode] = ex * similar
            gram = gram * inverse_both
            self.ledger[mode] = 0.5 * (gram + gram.transpose(0, 1, 3, 2))
            phi = phi * similar
            for i in range(3):
                if (mode >> i) & 1:
                    # row @ phi without BLAS: numpy's pairwise sum has a fixed order
                    self.impulse[mode, :, i] = np.sum(forces[i][None, :, None] * phi, axis=1)
                row = forces[i] if (mode >> i) & 1 else gaps[i]
                self.event_value[mode, i] = row
                self.event_slope[mode, i] = np.sum(row[:, None] * a, axis=0)
        self.force_rows = forces
        self.gap_rows = gaps
        self.velocity_rows = penetration_rows()[1]


def energy_terms(p: LumpedParameters, y: np.ndarray) -> dict:
    """Stored energy of state(s) y (..., 14): kinetic, elastic, gravity and downforce potentials (J)."""
    kinetic = 0.5 * (
        p.modal_mass_kg * y[..., IXD] ** 2
        + p.transducer_mass_kg * y[..., IZD] ** 2
        + p.free_mass_kg * y[..., IWD] ** 2
        + p.stem_mass_kg * y[..., IVD] ** 2
    )
    elastic = 0.5 * p.modal_stiffness_N_per_m * y[..., IX] ** 2
    for i, c in enumerate(p.contacts):
        elastic = elastic + 0.5 * c.stiffness_N_per_m * y[..., ID1 + i] ** 2
    gravity = p.gravity_m_per_s2 * (
        p.transducer_mass_kg * y[..., IZ] + p.free_mass_kg * y[..., IW] + p.stem_mass_kg * y[..., IV]
    )
    downforce = p.downforce_N * (y[..., IX] + y[..., IZ])
    return {
        "kinetic_J": kinetic,
        "elastic_J": elastic,
        "gravity_potential_J": gravity,
        "downforce_potential_J": downforce,
    }
