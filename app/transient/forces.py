"""Forces and kinematics the interactions share (app/transient/contact.py): the columns every contact
writes, the regularised Coulomb force of a point contact (the scalar twin of the UFL law, forms/contact_law.py)
and the velocity map of a point on a rotating rigid body."""

from __future__ import annotations

import numpy as np

from app import series as S
from forms import contact_law as law
from forms.contact_law import FrictionLaw


class ForceColumns:
    """The columns every contact writes: the force on the rigid body (the upper body of a link) and
    the closed flag."""

    name: str

    def columns(self) -> dict[str, str]:
        return S.contact_columns(self.name)

    def row(self, force_N, closed: bool) -> dict:
        return {S.contact_force(self.name): force_N, S.contact_closed(self.name): float(closed)}


# ------------------------------------------------------------------ friction of lumped interactions
def friction_of(section) -> FrictionLaw | None:
    """The friction law of a case's friction section (surface: its cap a shear stress; node and point
    contacts: a force), None without one."""
    if section is None:
        return None
    cap = section.shear_cap_Pa if hasattr(section, "shear_cap_Pa") else section.force_cap_N
    return FrictionLaw(section.mu_dynamic, section.static_ratio, section.decay_s_per_m, cap,
                       section.regularisation_speed_m_per_s)


def friction_force(slip: np.ndarray, normal_force_N: float, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regularised Coulomb force [N] opposing the tangential slip velocity ``slip`` (3-vector, m/s),
    the law of :func:`forms.contact.friction_traction` with forces instead of tractions (its scalar twin,
    :mod:`forms.contact_law`):

        F = -min(mu(|s|) N, cap) s / sqrt(|s|^2 + eps^2),  mu = mu_d (1 + (FACT - 1) exp(-DC |s|)).

    Returns (F, dF/ds (3 x 3), dF/dN (3))."""
    speed_sq = float(slip @ slip)
    speed = law.slip_speed(speed_sq)
    shear, d_shear_d_speed, d_shear_d_N = law.friction_shear(
        speed, normal_force_N, friction.mu_dynamic, friction.static_ratio, friction.decay_s_per_m,
        friction.shear_cap_Pa)
    reg = law.regularised_speed(speed_sq, friction.regularisation_speed_m_per_s)
    direction = slip / reg
    force = -shear * direction
    d_force_d_slip = (-shear * (np.eye(3) / reg - np.outer(slip, slip) / reg**3)
                      - d_shear_d_speed * np.outer(direction, slip / speed))
    return force, d_force_d_slip, -d_shear_d_N * direction


def skew(r: np.ndarray) -> np.ndarray:
    """[r]x with [r]x w = r x w."""
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def pad3(v) -> np.ndarray:
    out = np.zeros(3)
    v = np.asarray(v, dtype=float)
    out[: v.size] = v
    return out


def velocity_map(rigid, name: str, lever_m: np.ndarray) -> np.ndarray:
    """(3 x n_dofs) map from the body's generalised rates to the velocity of the point at
    ``lever_m`` (3-vector from its reference point): v + omega x r. Its transpose maps a force at
    that point to the generalised force (force, torques about the body's axes)."""
    body = rigid.body(name)
    translation = np.eye(3)[:, : rigid.gdim]
    rotation = -skew(lever_m) @ body.axis_vectors.T
    return np.hstack([translation, rotation])
