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
class implementing :class:`Interaction`, a schema dataclass in :mod:`app.case.transient` and one
entry here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from app.errors import CaseError
from app.transient.contact import NodeContact, ObstacleShape, PointContact, SurfaceContact
from app.transient.forces import friction_of


class Interaction(Protocol):
    name: str
    kind: str
    fe_coupled: bool              # acts on FE DOFs (local_dofs, dof_axes give the owned ones)
    # optional: ``reads_fields = False`` on an interaction with shared mid-point ``fields`` whose forms never read
    # them (a node contact reads system.u_mid and states directly): the system then keeps them up to date only for
    # the interactions that do (default: every interaction with ``fields``)

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
    friction = friction_of(section.friction)
    axes = ctx.rigid.body(section.body).axis_vectors if ctx.rigid is not None else None
    try:
        return SurfaceContact(section.name, ctx.fe, ctx.model.mesh_data.facet_tags, tag, section.body, shape,
                              section.stiffness, section.damping, friction=friction, weight=ctx.weight,
                              fields=ctx.fields, rotation_axes=axes,
                              exclude_initial_gap=section.exclude_initial_gap, rounding_m=section.rounding_m)
    except ValueError as exc:
        raise CaseError(ctx.file, f"{prefix}.shape", str(exc)) from None


def build_node(section, prefix: str, ctx: BuildContext):

    if section.node_point not in ctx.case.points:
        raise CaseError(ctx.file, f"{prefix}.node_point", f"unknown point {section.node_point!r} (see [points])")
    try:
        friction = friction_of(section.friction)
        return NodeContact(section.name, ctx.fe, ctx.case.points[section.node_point].coordinates_m, section.body,
                           section.radius_m, section.normal, section.stiffness, section.damping, fields=ctx.fields,
                           friction=friction)
    except ValueError as exc:
        raise CaseError(ctx.file, f"{prefix}.normal", str(exc)) from None


def build_point(section, prefix: str, ctx: BuildContext):

    _vector(section, "direction", section.direction, ctx, prefix)
    friction = friction_of(section.friction)
    return PointContact(section.name, section.lower, section.upper, section.direction, section.touch_distance_m,
                        section.stiffness, section.damping, friction=friction,
                        contact_offset_m=section.contact_offset_m)


INTERACTIONS = {"surface": build_surface, "node": build_node, "point": build_point}


def build_interactions(sections, ctx: BuildContext) -> list:
    """The interactions of ``[[transient.contacts]]``, in case order."""
    return [INTERACTIONS[s.kind](s, f"transient.contacts[{i}]", ctx) for i, s in enumerate(sections)]


