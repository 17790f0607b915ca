"""Interactions: everything that couples bodies in the transient analysis, behind one protocol.

An interaction (a penalty surface contact, a node contact, a rigid-rigid link, ...) owns

- its share of the condensed residual and tangent (:class:`app.transient.coupled.CoupledSystem`):
  ``add_residual`` adds its forces to the FE contact residual ``rc_S`` (at the contact DOFs), the
  rigid residual ``r_z`` (generalised: forces then torques) and, for diagnostics, a full FE vector;
  ``add_tangent`` adds its blocks d rc_S / d u_S (Kss), d rc_S / d z (B), d r_z / d u_S (L) and
  d r_z / d z (Kzz) at the evaluated iterate;
- its status for the step controller: closed or not, and the predicted time to closure [s];
- its stored (elastic penalty) energy [J] for the energy account;
- its time-series columns with units.

:data:`INTERACTIONS` maps the case's ``kind`` (``[[transient.contacts]]``) to a builder, so the
driver, the coupled system, the controller and the energy account iterate one list. A new kind is a
class implementing :class:`Interaction`, a schema dataclass in :mod:`app.transient.schema` and one
entry here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from app import series as S
from app.errors import CaseError


class Interaction(Protocol):
    name: str
    kind: str
    fe_coupled: bool              # acts on FE DOFs (local_dofs, dof_axes give the owned ones)

    def bind(self, system) -> None:
        """Check the bodies and take the contact-DOF layout of ``system`` (after it is set up)."""

    def move_to_iterate(self, system) -> None:
        """Take the body state of the current iterate (system.z_mid, zd_mid)."""

    def add_residual(self, system, rc_S: np.ndarray, r_z: np.ndarray, r) -> np.ndarray:
        """Add the residual (-forces) at the evaluated iterate; return the reported force [N]."""

    def add_tangent(self, system, Kss, B, L, Kzz) -> None:
        """Add the tangent blocks at the evaluated iterate (d / d end-of-step unknowns)."""

    def status(self, system, state) -> tuple[bool, float]:
        """(closed, time to closure [s], inf if not approaching) at ``state`` (the shared mid-point
        fields hold state.u, state.v)."""

    def stored_energy_J(self, system, state) -> float:
        """Elastic penalty energy [J] at ``state`` (the shared fields hold state.u)."""

    def dissipation_power_W(self, system) -> float:
        """Power [W] the interaction dissipates (damping, friction) at the evaluated iterate: the
        stepper integrates it into the interaction's dissipated energy."""

    def columns(self) -> dict[str, str]:
        """Time-series column names and units."""

    def row(self, force_N: np.ndarray, closed: bool) -> dict:
        """Time-series values of one record."""


class ForceColumns:
    """The columns every contact writes: the force on the rigid body (the upper body of a link) and
    the closed flag."""

    name: str

    def columns(self) -> dict[str, str]:
        return S.contact_columns(self.name)

    def row(self, force_N, closed: bool) -> dict:
        return {S.contact_force(self.name): force_N, S.contact_closed(self.name): float(closed)}


@dataclass
class BuildContext:
    """What a builder may need: the case, the transient FE model and the shared mid-point fields."""

    case: object
    model: object               # app.fe.model.FEModel
    fe: object                  # app.transient.fe.LinearFE
    fields: object              # app.transient.contact.MidpointFields
    weight: object              # volume weight of the model (2 pi r axisymmetric)
    gdim: int
    file: str
    rigid: object = None        # app.transient.rigid.RigidSet (rotation axes of the bodies)


def _vector(section, key: str, value, ctx: BuildContext, prefix: str):
    if value is not None and len(value) != ctx.gdim:
        raise CaseError(ctx.file, f"{prefix}.{key}", f"needs {ctx.gdim} components")
    return value


def build_surface(section, prefix: str, ctx: BuildContext):
    from app.fe.model import facet_group_tag
    from app.transient.contact import ObstacleShape, SurfaceContact

    tag = facet_group_tag(ctx.model.mesh_data.facet_names, section.facets, ctx.file, f"{prefix}.facets")
    if section.shape == "cone":
        if ctx.gdim != 3:
            raise CaseError(ctx.file, f"{prefix}.shape", f"a cone obstacle needs a 3D model (this one is {ctx.gdim}D)")
        try:
            shape = ObstacleShape("cone", radius_m=section.radius_m, axis=tuple(section.axis),
                                  half_angle_deg=section.half_angle_deg)
        except ValueError as exc:
            raise CaseError(ctx.file, f"{prefix}.axis", str(exc)) from None
    else:
        normal = _vector(section, "normal", section.normal, ctx, prefix)
        try:
            shape = (ObstacleShape("plane", normal=tuple(normal)) if section.shape == "plane"
                     else ObstacleShape("sphere", radius_m=section.radius_m, normal=tuple(normal or ())))
        except ValueError as exc:
            raise CaseError(ctx.file, f"{prefix}.normal", str(exc)) from None
    friction = section.friction.friction() if section.friction is not None else None
    axes = ctx.rigid.body(section.body).axis_vectors if ctx.rigid is not None else None
    try:
        return SurfaceContact(section.name, ctx.fe, ctx.model.mesh_data.facet_tags, tag, section.body, shape,
                              section.stiffness, section.damping, friction=friction, weight=ctx.weight,
                              fields=ctx.fields, rotation_axes=axes,
                              exclude_initial_gap=section.exclude_initial_gap)
    except ValueError as exc:
        raise CaseError(ctx.file, f"{prefix}.shape", str(exc)) from None


def build_node(section, prefix: str, ctx: BuildContext):
    from app.transient.contact import NodeContact

    if section.node_point not in ctx.case.points:
        raise CaseError(ctx.file, f"{prefix}.node_point", f"unknown point {section.node_point!r} (see [points])")
    try:
        friction = section.friction.friction() if section.friction is not None else None
        return NodeContact(section.name, ctx.fe, ctx.case.points[section.node_point].coordinates_m, section.body,
                           section.radius_m, section.normal, section.stiffness, section.damping, fields=ctx.fields,
                           friction=friction)
    except ValueError as exc:
        raise CaseError(ctx.file, f"{prefix}.normal", str(exc)) from None


def build_point(section, prefix: str, ctx: BuildContext):
    from app.transient.contact import PointContact

    _vector(section, "direction", section.direction, ctx, prefix)
    friction = section.friction.friction() if section.friction is not None else None
    return PointContact(section.name, section.lower, section.upper, section.direction, section.touch_distance_m,
                        section.stiffness, section.damping, friction=friction,
                        contact_offset_m=section.contact_offset_m)


INTERACTIONS = {"surface": build_surface, "node": build_node, "point": build_point}


def build_interactions(sections, ctx: BuildContext) -> list:
    """The interactions of ``[[transient.contacts]]``, in case order."""
    return [INTERACTIONS[s.kind](s, f"transient.contacts[{i}]", ctx) for i, s in enumerate(sections)]


# ------------------------------------------------------------------ friction of lumped interactions
def friction_force(slip: np.ndarray, normal_force_N: float, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regularised Coulomb force [N] opposing the tangential slip velocity ``slip`` (3-vector, m/s),
    the law of :func:`forms.contact.friction_traction` with forces instead of tractions:

        F = -min(mu(|s|) N, cap) s / sqrt(|s|^2 + eps^2),  mu = mu_d (1 + (FACT - 1) exp(-DC |s|)).

    Returns (F, dF/ds (3 x 3), dF/dN (3))."""
    eps = friction.regularisation_speed_m_per_s
    speed_sq = float(slip @ slip)
    speed = np.sqrt(speed_sq + 1e-30)
    reg = np.sqrt(speed_sq + eps * eps)
    decay = np.exp(-friction.decay_s_per_m * speed)
    mu = friction.mu_dynamic * (1 + (friction.static_ratio - 1) * decay)
    shear = mu * normal_force_N
    if shear > friction.shear_cap_Pa:
        shear, d_shear_d_speed, d_shear_d_N = friction.shear_cap_Pa, 0.0, 0.0
    else:
        d_shear_d_speed = -normal_force_N * friction.mu_dynamic * (friction.static_ratio - 1) \
            * friction.decay_s_per_m * decay
        d_shear_d_N = mu
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
