"""Penalty contacts: an FE surface against a rigid body, and Kelvin-Voigt links between rigid bodies.

:class:`SurfaceContact` compiles the UFL terms of :mod:`forms.contact` on one facet tag. The
residual and its tangent are evaluated at the generalised mid-point fields (u_mid, v_mid) that the
coupled system shares between all contacts; the body's mid-point position and velocity enter as
Constants, so nothing is recompiled while stepping.

:class:`PointContact` is a one-dimensional Kelvin-Voigt element between two rigid bodies (ball on
stem, stem on rock foundation): force = < k delta + c d(delta)/dt > while delta > 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix, assemble_vector, create_matrix, create_vector
from mpi4py import MPI
from petsc4py import PETSc

from app import series as S
from app.compat import is_mixed
from app.transient.active_set import DENSE_MAX
from app.transient.fe import LinearFE, displacement_of
from app.transient.forces import ForceColumns, friction_force, pad3, velocity_map
from forms import contact as cf
from forms.contact_law import FrictionLaw

# Regularised Coulomb friction parameters: the law's own record (forms/contact_law.py), shared by every tier.
Friction = FrictionLaw


@dataclass(frozen=True)
class ObstacleShape:
    """Shape of the rigid body seen by an FE surface: ``"plane"`` with outward unit ``normal``
    through the body position + ``offset_m``, or ``"sphere"`` of ``radius_m`` centred there; for a
    sphere an optional unit ``normal`` is the pole, the direction from the centre towards where
    contact happens, about which the gap is formed without round-off (large radii). ``"cone"``: a
    solid cone about the unit ``axis`` through the body position + ``offset_m``, whose conical face
    has ``radius_m`` there and makes ``half_angle_deg`` with the axis, its radius growing along
    ``axis`` (:func:`forms.contact.cone_gap`; 3D only)."""

    kind: str
    normal: tuple[float, ...] = ()
    radius_m: float = 0.0
    offset_m: tuple[float, ...] = ()
    axis: tuple[float, ...] = ()
    half_angle_deg: float = 0.0

    def __post_init__(self):
        if self.kind not in ("plane", "sphere", "cone"):
            raise ValueError(f"unknown obstacle shape {self.kind!r}")
        unit = bool(self.normal) and np.isclose(np.linalg.norm(self.normal), 1.0)
        if self.kind == "plane" and not unit:
            raise ValueError("a plane obstacle needs a unit normal")
        if self.kind == "sphere" and not self.radius_m > 0:
            raise ValueError("a sphere obstacle needs a positive radius")
        if self.kind == "sphere" and self.normal and not unit:
            raise ValueError("the pole of a sphere obstacle must be a unit vector")
        if self.kind == "cone":
            if len(self.axis) != 3 or not np.isclose(np.linalg.norm(self.axis), 1.0):
                raise ValueError("a cone obstacle needs a unit axis with 3 components")
            if not self.radius_m >= 0:
                raise ValueError("a cone obstacle needs a radius >= 0 at its reference point")
            if not 0.0 < self.half_angle_deg < 90.0:
                raise ValueError("the half angle of a cone obstacle must lie in (0, 90) degrees")

    @property
    def half_angle_rad(self) -> float:
        return math.radians(self.half_angle_deg)


class MidpointFields:
    """Fields and Constants shared by every surface contact of one model: the generalised mid-point
    displacement and velocity, d v_{n+1} / d u_{n+1} and 1 - alpha_f (set by the coupled system)."""

    def __init__(self, fe: LinearFE):
        mesh = fe.space.mesh
        self.u_mid = fem.Function(fe.space, name="u_mid")
        self.v_mid = fem.Function(fe.space, name="v_mid")
        self.velocity_per_displacement = fem.Constant(mesh, 0.0)
        self.one_minus_alpha_f = fem.Constant(mesh, 1.0)


class SurfaceContact(ForceColumns):
    """Penalty contact between FE facets (``tag`` in ``facet_tags``) and rigid body ``body``.

    ``stiffness_Pa_per_m`` is the penalty per unit area (pressure per metre of penetration),
    ``damping_Pa_s_per_m`` the normal viscous term; ``weight`` is the volume weight of the model
    (2 pi r for axisymmetric), so forces are those of the whole body of revolution.

    ``rotation_axes`` ((n_rot, 3) unit vectors, the body's rotation axes through its reference
    point) makes the obstacle rotate with the body: the relative velocity of a surface point is
    v - v_body - omega x r, r = y - p_body, so friction sees the spin and its torque acts on the
    body. The obstacle must be a body of revolution about every such axis (a sphere centred on the
    reference point, a plane normal to the axis in 3D, a cone about the axis through the reference
    point): its gap does not change with the angle, and
    omega x r has no normal component, so the rotation enters through friction only.

    ``exclude_initial_gap`` (ANSYS KEYOPT(9) = 1, every obstacle shape): the gap of each quadrature
    point is measured from its reference gap, the gap of the undeformed surface (u = 0) to the body at
    its reference position (the case's ``position_m``): g_eff = g(x + u, p) - g(x, p_ref)
    (:func:`forms.contact.excluding_initial_gap`). Both signs are excluded, as KEYOPT(9) = 1 does: every
    point of the facet group touches at the reference, none penetrates. This is meant for a surface that
    is in contact by design but is faceted (a straight-edged mesh of a curved face sags by h^2/(8 r)
    between its nodes); the nodal gaps of the step controller and of seating are measured the same way."""

    def __init__(self, name: str, fe: LinearFE, facet_tags, tag: int, body: str, shape: ObstacleShape,
                 stiffness_Pa_per_m: float, damping_Pa_s_per_m: float = 0.0, friction: Friction | None = None,
                 weight=1.0, fields: MidpointFields | None = None, quadrature_degree: int = 4,
                 rotation_axes=None, exclude_initial_gap: bool = False, rounding_m: float = 0.0):
        if not stiffness_Pa_per_m > 0:
            raise ValueError(f"contact {name!r}: stiffness must be > 0")
        fields = fields if fields is not None else MidpointFields(fe)
        self.fields = fields
        self.name, self.body, self.shape, self.fe = name, body, shape, fe
        mesh = fe.space.mesh
        gdim = fe.gdim
        facets = facet_tags.find(tag)
        self.local_dofs, self.dof_axes = fe.facet_displacement_dofs(facets)
        self.u_mid, self.v_mid = fields.u_mid, fields.v_mid
        self.velocity_per_displacement = fields.velocity_per_displacement
        self.one_minus_alpha_f = fields.one_minus_alpha_f
        # The body position enters as reference + displacement: the gap of a point is then
        # (x - p_ref).n + (u - dz).n. Forming x + u - p directly would round at eps |x| (1e-17 m on
        # a 0.1 m part), which a stiff penalty turns into residual noise that Newton cannot beat.
        self.body_reference = fem.Constant(mesh, np.zeros(gdim))
        self._pole_point = fem.Constant(mesh, np.zeros(gdim))
        self.body_displacement = fem.Constant(mesh, np.zeros(gdim))
        self.body_velocity = fem.Constant(mesh, np.zeros(gdim))
        self.stiffness = fem.Constant(mesh, float(stiffness_Pa_per_m))
        self.damping = fem.Constant(mesh, float(damping_Pa_s_per_m))
        # One quadrature rule for every contact form, so the force, the energy and the
        # "closed" indicator all see the same penetration points.
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags,
                         metadata={"quadrature_degree": quadrature_degree})(tag)
        self.ds, self.weight = ds, weight
        if shape.kind == "cone" and gdim != 3:
            raise ValueError(f"contact {name!r}: a cone obstacle needs a 3D model")
        self.exclude_initial_gap = bool(exclude_initial_gap)
        self.rotation_axes = np.zeros((0, 3)) if rotation_axes is None else np.asarray(rotation_axes, float)
        self._check_revolution(self.rotation_axes)
        omega = None
        if self.rotation_axes.size:
            self.body_angular_velocity = fem.Constant(mesh, np.zeros(3 if gdim == 3 else 1))
            omega = ufl.variable(self.body_angular_velocity)
        self.rounding_m = float(rounding_m)
        normal, gap, relative_velocity, gap_rate, lever = self._kinematics(
            displacement_of(self.u_mid), displacement_of(self.v_mid), self.body_displacement, self.body_velocity,
            omega)
        pressure = cf.normal_pressure(gap, gap_rate, self.stiffness, self.damping, self.rounding_m)
        traction = pressure * normal
        # dissipated power per area: damping (p minus its elastic part, times the penetration rate:
        # c rate^2, or the elastic energy lost while the clipped pressure is zero) + friction
        elastic = (self.stiffness * cf.macaulay(-gap) if not self.rounding_m
                   else cf.normal_pressure(gap, 0.0 * gap_rate, self.stiffness, 0.0, self.rounding_m))
        power = (pressure - elastic) * (-gap_rate)
        if friction is not None and friction.mu_dynamic > 0:     # mu = 0: no friction term (UFL zero)
            friction_traction = cf.friction_traction(
                normal, relative_velocity, pressure, friction.mu_dynamic, friction.static_ratio,
                friction.decay_s_per_m, friction.shear_cap_Pa, friction.regularisation_speed_m_per_s)
            traction = traction + friction_traction
            power = power - ufl.dot(friction_traction, relative_velocity)
        test = ufl.TestFunction(fe.space)
        trial = ufl.TrialFunction(fe.space)
        residual = cf.contact_residual(traction, displacement_of_test(test, fe), ds, weight)
        tangent = self.one_minus_alpha_f * (
            ufl.derivative(residual, self.u_mid, trial)
            + self.velocity_per_displacement * ufl.derivative(residual, self.v_mid, trial))
        self.residual_form = fem.form(residual)
        self.tangent_form = fem.form(tangent)
        if omega is not None:
            self._rotation_forms(traction, omega, lever, test, ds, weight, fe)
        self.energy_form = fem.form(cf.penalty_energy_density(gap, self.stiffness, self.rounding_m) * weight * ds)
        self.dissipation_form = fem.form(power * weight * ds)
        self.area_in_contact_form = fem.form(cf.heaviside(-gap) * weight * ds)
        self.normal_force_form = fem.form(pressure * weight * ds)
        self.residual_vector = create_vector(self.residual_form)
        self.tangent_matrix = create_matrix(self.tangent_form)
        self._coordinates = fe.dof_coordinates()
        self._node_dofs = self._group_dofs_by_node()
        self._nodal_reference_gap = np.zeros(self._node_dofs.shape[0])
        self.largest_reference_gap_m = 0.0

    def _kinematics(self, u, v, body_displacement, body_velocity, omega):
        """(outward normal, gap [m], relative velocity [m/s], gap rate [m/s], lever arm [m] or None) in UFL of
        the surface points y = x + u moving at v against the body displaced by ``body_displacement`` from its
        reference and moving at ``body_velocity`` (and spinning at ``omega``, a UFL variable, or None): the
        solver's forms take them at the mid-point fields, the pressure output (:meth:`pressure_probe`) at
        the state written."""
        mesh = self.fe.space.mesh
        gdim = self.fe.gdim
        x = ufl.SpatialCoordinate(mesh)
        offset = ufl.as_vector(self.shape.offset_m or (0.0,) * gdim)
        # y - point, with y = x + u and point = reference + dz + offset (see above)
        relative = (x - self.body_reference - offset) + (u - body_displacement)
        # e = y - (centre + R pole) for a sphere with a pole: (x - pole point at the reference) + (u - dz);
        # the pole point is summed once in floating point (set_body_reference), so e has no |centre| or
        # R-sized intermediate.
        normal, gap = self._gap_and_normal(relative, (x - self._pole_point) + (u - body_displacement))
        if self.exclude_initial_gap:
            # the same gap of the undeformed surface (u = 0) against the body at its reference position
            _, reference_gap = self._gap_and_normal(x - self.body_reference - offset, x - self._pole_point)
            gap = cf.excluding_initial_gap(gap, reference_gap)
        relative_velocity = v - body_velocity
        lever = None
        if omega is not None:
            # lever arm from the body's reference point, formed from small differences (see above)
            lever = (x - self.body_reference) + (u - body_displacement)
            spin = (ufl.cross(omega, lever) if gdim == 3
                    else omega[0] * ufl.as_vector((-lever[1], lever[0])))
            relative_velocity = relative_velocity - spin
        return normal, gap, relative_velocity, ufl.dot(relative_velocity, normal), lever

    def _gap_and_normal(self, relative, pole_relative):
        """(outward unit normal, gap [m]) of the obstacle in UFL, at the points ``relative`` = y - point
        (point = reference + body displacement + offset); ``pole_relative`` = y - (point + R pole) is
        used instead by a sphere with a pole (its gap without cancellation)."""
        shape = self.shape
        zero = ufl.as_vector((0.0,) * len(relative))
        if shape.kind == "plane":
            normal = ufl.as_vector(shape.normal)
            return normal, cf.plane_gap(relative, zero, normal)
        if shape.kind == "cone":
            axis = ufl.as_vector(shape.axis)
            return (cf.cone_normal(relative, axis, shape.half_angle_rad),
                    cf.cone_gap(relative, axis, shape.radius_m, shape.half_angle_rad))
        normal = cf.sphere_normal(relative, zero, shape.radius_m)
        if shape.normal:
            return normal, cf.sphere_gap_from_pole(pole_relative, ufl.as_vector(shape.normal), shape.radius_m)
        return normal, cf.sphere_gap(relative, zero, shape.radius_m)

    def _check_revolution(self, axes: np.ndarray) -> None:
        shape = self.shape
        for a in axes:
            offset = np.zeros(3)
            offset[: len(shape.offset_m)] = shape.offset_m or ()
            if shape.kind == "plane":
                normal = np.zeros(3)
                normal[: len(shape.normal)] = shape.normal
                ok = len(shape.normal) == 3 and np.linalg.norm(np.cross(a, normal)) < 1e-12
            elif shape.kind == "cone":
                # invariant under rotations about its own axis, when that axis is the rotation
                # axis through the reference point
                ok = (np.linalg.norm(np.cross(a, shape.axis)) < 1e-12
                      and np.linalg.norm(np.cross(a, offset)) < 1e-15)
            else:
                ok = np.linalg.norm(np.cross(a, offset)) < 1e-15
            if not ok:
                raise ValueError(f"contact {self.name!r}: the {shape.kind} obstacle is not a body of revolution "
                                 f"about the rotation axis {a.tolist()} of body {self.body!r}")

    def _rotation_forms(self, traction, omega, lever, test, ds, weight, fe) -> None:
        """Forms of the rotation coupling, per rotation axis a_k: d(residual)/d(omega_k) (vector),
        the torque of the contact on the body about a_k (scalar: int (r x -t) . a_k) with its
        derivatives d/du_mid, d/dv_mid (vectors) and d/d(omega_j) (scalars)."""
        gdim = fe.gdim
        force = -traction                       # on the body, per area

        def about(k):
            if gdim == 3:
                return ufl.dot(ufl.cross(lever, force), ufl.as_vector(self.rotation_axes[k].tolist()))
            return lever[0] * force[1] - lever[1] * force[0]

        def d_omega(expr, k):
            derivative = ufl.diff(expr, omega)
            if gdim == 3:
                return ufl.dot(derivative, ufl.as_vector(self.rotation_axes[k].tolist()))
            return derivative[0] if len(expr.ufl_shape) == 0 else ufl.as_vector(
                [derivative[i, 0] for i in range(gdim)])

        n_rot = self.rotation_axes.shape[0]
        self.torque_forms = [fem.form(about(k) * weight * ds) for k in range(n_rot)]
        self.residual_per_spin_forms = [
            fem.form(cf.contact_residual(d_omega(traction, k), displacement_of_test(test, fe), ds, weight))
            for k in range(n_rot)]
        self.torque_per_u_forms = [fem.form(ufl.derivative(about(k) * weight * ds, self.u_mid, test)
                                            + self.velocity_per_displacement
                                            * ufl.derivative(about(k) * weight * ds, self.v_mid, test))
                                   for k in range(n_rot)]
        self.torque_per_spin_forms = [[fem.form(d_omega(about(k), j) * weight * ds) for j in range(n_rot)]
                                      for k in range(n_rot)]

    def set_body_reference(self, position_m: np.ndarray) -> None:
        """Fix the reference position of the body (its initial position; any fixed value works,
        a value close to the motion keeps the gap's round-off small)."""
        self.body_reference.value[:] = position_m
        if self.shape.kind == "sphere" and self.shape.normal:
            offset = np.asarray(self.shape.offset_m) if self.shape.offset_m else 0.0
            self._pole_point.value[:] = (np.asarray(position_m, dtype=float) + offset
                                         + self.shape.radius_m * np.asarray(self.shape.normal))
        zero = np.zeros(self._coordinates.shape[0])
        self._nodal_reference_gap = self._raw_nodal_gaps(zero, zero, position_m, np.zeros(len(position_m)))[0]
        local = float(np.abs(self._nodal_reference_gap).max(initial=0.0))
        #: largest |gap| of a contact node at the reference [m]: what exclude_initial_gap removes
        self.largest_reference_gap_m = self.fe.comm.allreduce(local, op=MPI.MAX)

    def set_body_state(self, position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> None:
        self.body_displacement.value[:] = np.asarray(position_m) - self.body_reference.value
        self.body_velocity.value[:] = velocity_m_per_s

    def assemble_residual(self) -> PETSc.Vec:
        """Contact residual (-f_contact) at the current mid-point fields; Dirichlet rows zeroed."""
        b = self.residual_vector
        with b.localForm() as local:
            local.set(0.0)
        assemble_vector(b, self.residual_form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.fe.zero_constrained(b)
        return b

    def assemble_tangent(self) -> PETSc.Mat:
        A = self.tangent_matrix
        A.zeroEntries()
        assemble_matrix(A, self.tangent_form)
        A.assemble()
        return A

    def elastic_energy_J(self) -> float:
        comm = self.fe.comm
        return comm.allreduce(fem.assemble_scalar(self.energy_form), op=MPI.SUM)

    def area_in_contact_m2(self) -> float:
        return self.fe.comm.allreduce(fem.assemble_scalar(self.area_in_contact_form), op=MPI.SUM)

    # Nodal gaps, for the step controller (where will contact open or close next?)
    def _group_dofs_by_node(self) -> np.ndarray:
        """(n_nodes, gdim) local DOF numbers of the contact nodes owned here (component order)."""
        gdim = self.fe.gdim
        if self.local_dofs.size == 0:
            return np.zeros((0, gdim), dtype=np.int32)
        coords = self._coordinates[self.local_dofs]
        scale = max(np.abs(coords).max(), 1e-30)
        keys = np.round(coords / scale, 10)
        _, node = np.unique(keys, axis=0, return_inverse=True)
        node = node.reshape(-1)
        out = np.full((node.max() + 1, gdim), -1, dtype=np.int64)
        out[node, self.dof_axes] = self.local_dofs
        return out[(out >= 0).all(axis=1)]

    def nodal_gaps(self, u: np.ndarray, v: np.ndarray, body_position, body_velocity):
        """(gap [m], gap rate [m/s]) at the owned contact nodes for local DOF arrays u, v (with
        ``exclude_initial_gap``, from each node's reference gap, as the forms)."""
        gap, rate = self._raw_nodal_gaps(u, v, body_position, body_velocity)
        if self.exclude_initial_gap:
            gap = gap - self._nodal_reference_gap
        return gap, rate

    def _raw_nodal_gaps(self, u: np.ndarray, v: np.ndarray, body_position, body_velocity):
        nodes = self._node_dofs
        if nodes.shape[0] == 0:
            return np.zeros(0), np.zeros(0)
        x = self._coordinates[nodes[:, 0]]
        y = x + u[nodes]
        rel_v = v[nodes] - np.asarray(body_velocity)
        point = np.asarray(body_position) + (np.asarray(self.shape.offset_m) if self.shape.offset_m else 0.0)
        if self.shape.kind == "plane":
            n = np.asarray(self.shape.normal)
            return (y - point) @ n, rel_v @ n
        if self.shape.kind == "cone":
            return self._cone_gaps(x, u[nodes], rel_v, point)
        d = y - point
        dist = np.linalg.norm(d, axis=1)
        return dist - self.shape.radius_m, np.einsum("ij,ij->i", d / dist[:, None], rel_v)

    def smallest_nodal_gap_m(self, u: np.ndarray, body_position) -> float:
        """Smallest gap [m] of the contact nodes (all ranks) at displacement ``u`` with the body at
        ``body_position``."""
        gap, _ = self.nodal_gaps(u, np.zeros_like(u), body_position, np.zeros(len(body_position)))
        return self.fe.comm.allreduce(float(gap.min(initial=math.inf)), op=MPI.MIN)

    def seat_distance_m(self, u: np.ndarray, body_position, direction, tolerance_m: float = 1e-13) -> float:
        """Distance s [m] to move the body from ``body_position`` along the unit ``direction`` so that
        the smallest nodal gap at ``u`` is zero: the body just touches the surface's highest point.
        Secant iteration on s -> min gap (linear in s for a plane or a cone moved along its normal or
        axis: one step). ValueError if moving along ``direction`` does not open the contact."""
        position = np.asarray(body_position, dtype=float)
        direction = np.asarray(direction, dtype=float)

        def smallest(s):
            return self.smallest_nodal_gap_m(u, position + s * direction)

        s, g = 0.0, smallest(0.0)
        if not math.isfinite(g):
            raise ValueError(f"contact {self.name!r} has no nodes to seat on")
        step = max(abs(g), 1e-9)
        for _ in range(50):
            if abs(g) <= tolerance_m:
                return s
            g_next = smallest(s + step)
            slope = (g_next - g) / step
            if not slope > 0:
                raise ValueError(f"contact {self.name!r}: moving body {self.body!r} along {direction.tolist()} "
                                 "does not open the contact, so it cannot be seated")
            s, g = s + step, g_next
            step = -g / slope
        raise ValueError(f"contact {self.name!r}: seating body {self.body!r} did not converge (gap {g:.3g} m)")

    def _cone_gaps(self, x, u_nodes, rel_v, body_position):
        """(gap [m], gap rate [m/s]) of points x + u to the cone (forms.contact.cone_gap), with the
        position relative to the reference point formed from small differences as in the forms."""
        shape = self.shape
        a = np.asarray(shape.axis)
        alpha = shape.half_angle_rad
        reference = self.body_reference.value
        d = (x - reference) + (u_nodes - (np.asarray(body_position) - reference))
        if shape.offset_m:
            d = d - np.asarray(shape.offset_m)
        h = d @ a
        radial = d - np.outer(h, a)
        rho = np.linalg.norm(radial, axis=1)
        gap = (rho - shape.radius_m - h * math.tan(alpha)) * math.cos(alpha)
        normal = math.cos(alpha) * radial / rho[:, None] - math.sin(alpha) * a
        return gap, np.einsum("ij,ij->i", normal, rel_v)

    # ------------------------------------------------------------ interaction protocol
    kind = "surface"
    fe_coupled = True

    def bind(self, system) -> None:
        rigid = system.rigid
        if self.body not in rigid.index:
            raise ValueError(f"contact {self.name!r} names unknown rigid body {self.body!r}")
        body = rigid.body(self.body)
        if body.axis_vectors.shape != self.rotation_axes.shape or not np.allclose(body.axis_vectors,
                                                                                 self.rotation_axes):
            raise ValueError(f"contact {self.name!r}: built for rotation axes {self.rotation_axes.tolist()}, "
                             f"body {self.body!r} has {body.axis_vectors.tolist()}")
        self.set_body_reference(body.position_m)

    def move_to_iterate(self, system) -> None:
        sl = system.rigid.dofs(self.body)
        self.set_body_state(system.z_mid[sl], system.zd_mid[sl])
        if self.rotation_axes.size:
            self._set_spin(system.rigid.angular_velocity(self.body, system.zd_mid))

    def _set_spin(self, omega: np.ndarray) -> None:
        self.body_angular_velocity.value[:] = omega if self.fe.gdim == 3 else omega[2:]

    def _scalar(self, form) -> float:
        return self.fe.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)

    def _vector_at_S(self, system, form) -> np.ndarray:
        vectors = self.__dict__.setdefault("_form_vectors", {})
        vec = vectors.get(id(form))
        if vec is None:
            vec = vectors[id(form)] = create_vector(form)    # one per form, reused (a full-size vector)
        with vec.localForm() as local:
            local.set(0.0)
        assemble_vector(vec, form)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.fe.zero_constrained(vec)
        return system._gather_S(vec.array_r)

    def torque_N_m(self) -> np.ndarray:
        """Torque of the contact on the body about its rotation axes [N m] (current fields)."""
        return np.array([self._scalar(f) for f in self.torque_forms])

    def add_residual(self, system, rc_S, r_z, r):
        rc = self.assemble_residual()
        if r is not None:
            r.axpy(1.0, rc)
        rc_S += system._gather_S(rc.array_r)
        force = np.array([rc.dot(tk) for tk in system.translations])
        r_z[system.rigid.dofs(self.body)] -= force
        if self.rotation_axes.size:
            torque = self.torque_N_m()
            r_z[system.rigid.rotation_dofs(self.body)] -= torque
            return np.concatenate([force, torque])
        return force

    def columns(self) -> dict[str, str]:
        out = super().columns()
        if self.rotation_axes.size:
            out[S.contact_torque(self.name)] = "N m (on the rigid body, about its rotation axes)"
            out[S.contact_normal_force(self.name)] = "N"
            out[S.contact_area(self.name)] = "m^2"
        return out

    def row(self, force_N, closed: bool) -> dict:
        gdim = self.fe.gdim
        out = super().row(force_N[:gdim], closed)
        if self.rotation_axes.size:
            # the fields hold the accepted step's end (mid) state and the body its end state (status())
            out[S.contact_torque(self.name)] = force_N[gdim:]
            out[S.contact_normal_force(self.name)] = self._scalar(self.normal_force_form)
            out[S.contact_area(self.name)] = self.area_in_contact_m2()
        return out

    def add_tangent(self, system, Kss, B, L, Kzz) -> None:
        block = system.contact_tangent_block(self.assemble_tangent())      # sparse, s x s
        T = system.translation_S
        Kss += block
        sl = system.rigid.dofs(self.body)
        B[:, sl] -= block @ T
        L[sl, :] -= T.T @ block
        Kzz[sl, sl] += T.T @ block @ T
        if self.rotation_axes.size:
            self._add_rotation_tangent(system, B, L, Kzz, sl)

    def _add_rotation_tangent(self, system, B, L, Kzz, sl) -> None:
        """Blocks of the body's angles (see _rotation_forms): the residual and the torque depend on
        omega_mid ((1 - alpha_f) c_vel per end-of-step angle), and on u, v and the body position
        through differences, so d/dz = -(d/du) . translation."""
        scale = (1 - system.scheme.alpha_f)
        c_vel = system.c_vel
        rot = np.arange(system.rigid.size)[system.rigid.rotation_dofs(self.body)]
        T = system.translation_S
        n_rot = rot.size
        for j in range(n_rot):
            column = scale * c_vel * self._vector_at_S(system, self.residual_per_spin_forms[j])
            B[:, rot[j]] += column
            Kzz[sl, rot[j]] -= T.T @ column
        for k in range(n_rot):
            row = -scale * self._vector_at_S(system, self.torque_per_u_forms[k])
            L[rot[k], :] += row
            Kzz[rot[k], sl] -= row @ T
            for j in range(n_rot):
                Kzz[rot[k], rot[j]] -= scale * c_vel * self._scalar(self.torque_per_spin_forms[k][j])

    def status(self, system, state) -> tuple[bool, float]:
        sl = system.rigid.dofs(self.body)
        self.set_body_state(state.z[sl], state.zd[sl])
        # Closed = penetration at a quadrature point (what the force sees); the closure time is
        # predicted from the nodes (a curved obstacle can dip between them: a warning sign of a
        # too coarse contact mesh, not an error).
        closed = self.area_in_contact_m2() > 0.0
        gap, rate = self.nodal_gaps(state.u, state.v, state.z[sl], state.zd[sl])
        approaching = (gap > 0) & (rate < 0)
        local = float(np.min(gap[approaching] / -rate[approaching])) if approaching.any() else math.inf
        return closed, self.fe.comm.allreduce(local, op=MPI.MIN)

    def stored_energy_J(self, system, state) -> float:
        sl = system.rigid.dofs(self.body)
        self.set_body_state(state.z[sl], state.zd[sl])
        return self.elastic_energy_J()

    def dissipation_power_W(self, system) -> float:
        """Power dissipated by damping and friction [W] at the evaluated iterate (the fields and the
        body state of the last evaluation)."""
        return self._scalar(self.dissipation_form)


class ContactPressureProbe:
    """The normal contact pressure p [Pa] of a :class:`SurfaceContact` as a P1 field on the FE mesh: the solver's
    own law (:func:`forms.contact.normal_pressure` of the gap and gap rate of :meth:`SurfaceContact._kinematics`,
    the same UFL) at the vertices of the contact's facets, zero at every other vertex.

    A vertex's value is the law's average over the facets round it, weighted by the vertex's hat function phi_i
    (the lumped L2 projection onto the surface's P1 functions): p_i = int p phi_i w ds / int phi_i w ds, with the
    contact's own quadrature rule and volume weight w (2 pi r axisymmetric). So the field integrates to the
    contact's normal force exactly (sum_i p_i int phi_i w ds = int p w ds), and a vertex next to a penetrating
    quadrature point shows it even where the vertex itself is not inside the obstacle (a faceted curved face
    touches between its nodes, docs/contact.md). A smooth pressure is smoothed by O(h^2): -0.15 % at the centre
    of a Hertz patch 10 elements across its radius.

    It is taken at a given state (:meth:`evaluate`: the end-of-step u, v and body position and velocity, the
    state a field file shows), not at the generalised mid-point the step's equilibrium uses; the two coincide
    for Newmark (alpha_f = 0) and at rest. Friction is not part of it (a normal pressure)."""

    def __init__(self, contact: SurfaceContact):
        from app.compat import scalar_space

        self.contact = contact
        fe = contact.fe
        mesh = fe.space.mesh
        gdim = fe.gdim
        self.u = fem.Function(fe.space)
        self.v = fem.Function(fe.space)
        self.body_displacement = fem.Constant(mesh, np.zeros(gdim))
        self.body_velocity = fem.Constant(mesh, np.zeros(gdim))
        self.body_angular_velocity = None
        omega = None
        if contact.rotation_axes.size:
            self.body_angular_velocity = fem.Constant(mesh, np.zeros(3 if gdim == 3 else 1))
            omega = self.body_angular_velocity
        _, gap, _, gap_rate, _ = contact._kinematics(displacement_of(self.u), displacement_of(self.v),
                                                     self.body_displacement, self.body_velocity, omega)
        pressure = cf.normal_pressure(gap, gap_rate, contact.stiffness, contact.damping, contact.rounding_m)
        self.space = scalar_space(mesh, "Lagrange", 1)
        self.pressure = fem.Function(self.space, name="contact_pressure_Pa")
        hat = ufl.TestFunction(self.space)
        ds = contact.ds
        self._moment_form = fem.form(pressure * hat * contact.weight * ds)
        self._moment = create_vector(self._moment_form)
        area = self._assembled(fem.form(hat * contact.weight * ds))
        self._on_surface = area > 0
        self._area = np.where(self._on_surface, area, 1.0)
        self._n_owned = self.space.dofmap.index_map.size_local

    def _assembled(self, form, vector=None) -> np.ndarray:
        """The facet integral ``form`` against the P1 hat functions, summed over the ranks, at the local vertices
        (owned and ghosts)."""
        b = vector if vector is not None else create_vector(form)
        with b.localForm() as local:
            local.set(0.0)
        assemble_vector(b, form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        b.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with b.localForm() as local:
            values = np.array(local.array_r)
        if vector is None:
            b.destroy()
        return values

    def evaluate(self, state, position_m, velocity_m_per_s, angular_velocity=None) -> fem.Function:
        """The pressure field [Pa] at the FE state (``state.u``, ``state.v``: local arrays of the FE space) with the
        body at ``position_m`` moving at ``velocity_m_per_s`` (and spinning at ``angular_velocity``, (3,))."""
        contact = self.contact
        self.u.x.array[:] = state.u
        self.v.x.array[:] = state.v
        self.body_displacement.value[:] = np.asarray(position_m) - contact.body_reference.value
        self.body_velocity.value[:] = velocity_m_per_s
        if self.body_angular_velocity is not None:
            omega = np.asarray(angular_velocity, dtype=float)
            self.body_angular_velocity.value[:] = omega if contact.fe.gdim == 3 else omega[2:]
        moment = self._assembled(self._moment_form, self._moment)
        self.pressure.x.array[:] = np.where(self._on_surface, moment / self._area, 0.0)
        return self.pressure

    def peak_Pa(self) -> float:
        """The largest pressure of the last :meth:`evaluate` over every rank's vertices [Pa]."""
        local = float(self.pressure.x.array[:self._n_owned].max(initial=0.0))
        return self.contact.fe.comm.allreduce(local, op=MPI.MAX)


def displacement_of_test(test, fe: LinearFE):
    if is_mixed(fe.space):
        return ufl.split(test)[0]
    return test


class PointContact(ForceColumns):
    """Kelvin-Voigt contact between rigid bodies ``lower`` and ``upper`` along unit ``normal``
    (pointing from lower to upper). Penetration delta = touch_distance - normal . (z_upper - z_lower);
    normal force f = < k delta + c d(delta)/dt > for delta > 0 (no pull), pushing the bodies apart.

    With ``friction``, the contact point sits ``contact_offset_m`` from the upper body's reference
    point against the normal (a disc or ball of that radius on the lower body); the slip is the
    tangential part of the relative velocity there, v_up + omega_up x r_up - (v_lo + omega_lo x r_lo),
    and the regularised Coulomb force (:func:`app.transient.forces.friction_force`, the cap
    a force) acts on the upper body with its torque about each body's rotation axes. The lever arm
    of the lower body follows the current positions; its change within a step is left out of the
    tangent (Newton then converges linearly in that term, the residual is exact)."""

    kind = "point"
    fe_coupled = False

    def __init__(self, name: str, lower: str, upper: str, normal, touch_distance_m: float,
                 stiffness_N_per_m: float, damping_N_s_per_m: float = 0.0, friction: Friction | None = None,
                 contact_offset_m: float = 0.0):
        if not stiffness_N_per_m > 0:
            raise ValueError(f"contact {name!r}: stiffness must be > 0")
        if damping_N_s_per_m < 0:
            raise ValueError(f"contact {name!r}: damping must be >= 0")
        self.name, self.lower, self.upper = name, lower, upper
        self.normal = np.asarray(normal, dtype=float)
        self.normal /= np.linalg.norm(self.normal)
        self.touch_distance_m = float(touch_distance_m)
        self.stiffness_N_per_m = float(stiffness_N_per_m)
        self.damping_N_s_per_m = float(damping_N_s_per_m)
        self.friction = friction
        self.contact_offset_m = float(contact_offset_m)
        self._normal_values = self.normal.tolist()
        self._bound_rigid = self._lower_dofs = self._upper_dofs = None     # set by bind
        self._iterate_key = None          # (system, rigid_version) of the values _at_iterate keeps

    def penetration(self, z_lower, z_upper, v_lower, v_upper):
        """(delta [m], d(delta)/dt [m/s])."""
        # in Python floats: the bodies' few coordinates cost more as numpy calls than as arithmetic
        separation = rate = 0.0
        for n_k, zl, zu, vl, vu in zip(self._normal_values, _values(z_lower), _values(z_upper), _values(v_lower),
                                       _values(v_upper)):
            separation += n_k * (zu - zl)
            rate -= n_k * (vu - vl)
        return self.touch_distance_m - separation, rate

    def force(self, delta: float, rate: float) -> tuple[float, float, float]:
        """(f [N], df/d delta [N/m], df/d rate [N s/m])."""
        if delta <= 0.0:
            return 0.0, 0.0, 0.0
        f = self.stiffness_N_per_m * delta + self.damping_N_s_per_m * rate
        if f <= 0.0:
            return 0.0, 0.0, 0.0
        return f, self.stiffness_N_per_m, self.damping_N_s_per_m

    def elastic_energy_J(self, delta: float) -> float:
        return 0.5 * self.stiffness_N_per_m * max(delta, 0.0) ** 2

    # ------------------------------------------------------------ interaction protocol
    def bind(self, system) -> None:
        rigid = system.rigid
        for name in (self.lower, self.upper):
            if name not in rigid.index:
                raise ValueError(f"contact {self.name!r} names unknown rigid body {name!r}")
        # Generalised path (lever arms, torques) only where it can act: friction, or a rotating body.
        self._general = self.friction is not None or bool(
            rigid.body(self.lower).rotation_axes or rigid.body(self.upper).rotation_axes)
        self._pair = np.r_[np.arange(rigid.size)[rigid.all_dofs(self.lower)],
                           np.arange(rigid.size)[rigid.all_dofs(self.upper)]]
        self._bound_rigid = rigid
        self._lower_dofs, self._upper_dofs = rigid.dofs(self.lower), rigid.dofs(self.upper)
        self._normal_outer = np.outer(self.normal, self.normal)
        n_lo = rigid.body(self.lower).n_dofs
        self._D = np.zeros(self._pair.size)        # d delta / d (lower, upper) coordinates
        self._D[:rigid.gdim] = self.normal
        self._D[n_lo:n_lo + rigid.gdim] = -self.normal

    def move_to_iterate(self, system) -> None:
        pass

    def _state(self, rigid, z, zd):
        if rigid is self._bound_rigid:
            lo, up = self._lower_dofs, self._upper_dofs
        else:
            lo, up = rigid.dofs(self.lower), rigid.dofs(self.upper)
        return self.penetration(z[lo], z[up], zd[lo], zd[up])

    def _at_iterate(self, system) -> tuple[float, float, tuple[float, float, float]]:
        """(delta, rate, force(delta, rate)) at the system's rigid mid-point state, kept while its
        ``rigid_version`` stays (the residual, the tangent and the dissipation of one iterate)."""
        key = (system, getattr(system, "rigid_version", None))
        if key[1] is None:
            delta, rate = self._state(system.rigid, system.z_mid, system.zd_mid)
            self._iterate_values = (delta, rate, self.force(delta, rate))
        elif self._iterate_key != key:
            z, zd = system.rigid_mid_values()
            lo, up = self._lower_dofs, self._upper_dofs
            delta, rate = self.penetration(z[lo], z[up], zd[lo], zd[up])
            self._iterate_values = (delta, rate, self.force(delta, rate))
            self._iterate_key = key
        return self._iterate_values

    def _slip_map(self, rigid, z) -> np.ndarray:
        """P: (lower, upper) coordinate rates -> velocity of the upper body's contact point relative
        to the lower body's (3-vector)."""
        n3 = pad3(self.normal)
        r_up = -self.contact_offset_m * n3
        r_lo = pad3(z[rigid.dofs(self.upper)] - z[rigid.dofs(self.lower)]) + r_up
        return np.hstack([-velocity_map(rigid, self.lower, r_lo), velocity_map(rigid, self.upper, r_up)])

    def _general_terms(self, system, tangent: bool):
        """(generalised force on (lower, upper) [N, N m], force on upper [N], tangent or None)."""
        rigid = system.rigid
        z, zd = system.z_mid, system.zd_mid
        f, k_f, c_f = self.force(*self._state(rigid, z, zd))
        n3 = pad3(self.normal)
        P = self._slip_map(rigid, z)
        F = f * n3
        dF_ds, dF_dN = np.zeros((3, 3)), np.zeros(3)
        if self.friction is not None and f > 0.0:
            tangential = np.eye(3) - np.outer(n3, n3)
            F_t, dF_ds, dF_dN = friction_force(tangential @ (P @ zd[self._pair]), f, self.friction)
            F = F + F_t
            dF_ds = dF_ds @ tangential
        generalised = P.T @ F
        if not tangent:
            return generalised, F[: rigid.gdim], None
        # d F / d (end-of-step coordinates): positions through delta, rates through delta and slip
        one_minus_af = 1 - system.scheme.alpha_f
        dF_dq = np.outer(n3 + dF_dN, (k_f + c_f * system.c_vel) * self._D) + system.c_vel * dF_ds @ P
        return generalised, F[: rigid.gdim], -one_minus_af * P.T @ dF_dq

    def tangent_key(self, system):
        """What :meth:`add_tangent` depends on besides dt: (df/d delta, df/d rate) at the iterate; None on the
        generalised path (friction, rotations), whose tangent depends on the positions."""
        return None if self._general else self._at_iterate(system)[2][1:]

    def add_residual(self, system, rc_S, r_z, r):
        if self._general:
            generalised, force, _ = self._general_terms(system, tangent=False)
            r_z[self._pair] -= generalised
            return force
        f = self._at_iterate(system)[2][0]
        force = f * self.normal
        if f != 0.0:        # open: nothing to add
            r_z[self._upper_dofs] -= force
            r_z[self._lower_dofs] += force
        return force

    def add_tangent(self, system, Kss, B, L, Kzz) -> None:
        if self._general:
            _, _, block = self._general_terms(system, tangent=True)
            Kzz[np.ix_(self._pair, self._pair)] += block
            return
        _, k_f, c_f = self._at_iterate(system)[2]
        if k_f == 0.0 and c_f == 0.0:
            return      # open: no block
        stiffness = (1 - system.scheme.alpha_f) * (k_f + c_f * system.c_vel) * self._normal_outer
        lo, up = self._lower_dofs, self._upper_dofs
        Kzz[up, up] += stiffness
        Kzz[lo, lo] += stiffness
        Kzz[up, lo] -= stiffness
        Kzz[lo, up] -= stiffness

    def status(self, system, state) -> tuple[bool, float]:
        delta, rate = self._state(system.rigid, state.z, state.zd)
        return delta > 0, (-delta / rate if delta <= 0 and rate > 0 else math.inf)

    def stored_energy_J(self, system, state) -> float:
        return self.elastic_energy_J(self._state(system.rigid, state.z, state.zd)[0])

    def dissipation_power_W(self, system) -> float:
        """Power dissipated by the damper and friction [W] at the evaluated iterate."""
        rigid, z, zd = system.rigid, system.z_mid, system.zd_mid
        delta, rate, (f, _, _) = self._at_iterate(system)
        if delta <= 0.0:
            return 0.0
        power = (f - self.stiffness_N_per_m * delta) * rate
        if self.friction is not None and f > 0.0:
            n3 = pad3(self.normal)
            slip = (np.eye(3) - np.outer(n3, n3)) @ (self._slip_map(rigid, z) @ zd[self._pair])
            power -= float(friction_force(slip, f, self.friction)[0] @ slip)
        return float(power)


class NodeContact(ForceColumns):
    """One FE node against a sphere of a rigid body, with a Hertz force law (node-to-body contact).

    For the axisymmetric drill, a ball touching the tip face loads a disc of radius
    a = sqrt(R delta) (~0.1 mm at 100 N), far below practical element sizes, so no facet quadrature
    point sees it. The tip's axis node carries the contact instead, with the Hertz law of a sphere
    on a flat (Johnson, *Contact Mechanics*, eq. 4.23): F = (4/3) E* sqrt(R) delta^(3/2), where
    1/E* = (1 - nu_1^2)/E_1 + (1 - nu_2^2)/E_2; ``stiffness_N_per_m1_5`` is (4/3) E* sqrt(R). The
    local Hertz indentation is what the mesh cannot resolve; the bulk compliance of the tip stays
    with the FE model. An optional damper adds c d(delta)/dt (clipped: no pull).

    Gap along the unit ``normal`` (from the body centre towards the FE node):
    g = normal . (y - c) - R, y = x_node + u (the node stays on the line of centres; the
    axisymmetric axis). ``local_dofs``/``dof_axes`` are the node's owned displacement DOFs with a
    non-zero normal component (empty on the other ranks); the residual on them is -F n_k.

    With ``friction`` (the cap a force) the node also carries the regularised Coulomb force of its
    slip against the sphere's surface point R n, v_node - (v_body + omega x R n) projected on the
    tangent plane; it then owns all its free displacement DOFs, and the force's torque acts on
    the body's rotations (the sphere is a body of revolution about any axis: its spin enters
    through friction only)."""

    def __init__(self, name: str, fe: LinearFE, point_m, body: str, radius_m: float, normal,
                 stiffness_N_per_m1_5: float, damping_N_s_per_m: float = 0.0, fields: MidpointFields | None = None,
                 friction: Friction | None = None):
        if not stiffness_N_per_m1_5 > 0:
            raise ValueError(f"contact {name!r}: stiffness must be > 0")
        if not radius_m > 0:
            raise ValueError(f"contact {name!r}: radius must be > 0")
        n = np.asarray(normal, dtype=float)
        if n.size != fe.gdim or not np.isclose(np.linalg.norm(n), 1.0):
            raise ValueError(f"contact {name!r}: normal must be a unit vector with {fe.gdim} components")
        self.name, self.body, self.fe = name, body, fe
        self.fields = fields if fields is not None else MidpointFields(fe)
        self.normal = n
        self._normal_values = n.tolist()
        self._iterate_key = None          # (system, iterate_version) of the values _at_iterate keeps
        self.friction = friction
        self.radius_m = float(radius_m)
        self.stiffness = float(stiffness_N_per_m1_5)
        self.damping = float(damping_N_s_per_m)
        self.comm = fe.comm
        coords = fe.dof_coordinates()
        point = np.asarray(point_m, dtype=float)[: fe.gdim]
        dofs, axes = [], []
        for k in range(fe.gdim):
            _, sub = fe.displacement_space.sub(k).collapse()
            sub = np.asarray(sub)
            sub = sub[sub < fe.n_owned]
            dist = np.linalg.norm(coords[sub] - point, axis=1) if sub.size else np.zeros(0)
            best = float(dist.min()) if sub.size else np.inf
            owner_best = self.comm.allreduce((best, self.comm.rank), op=MPI.MINLOC)
            if owner_best[1] == self.comm.rank and (n[k] != 0.0 or friction is not None):
                dofs.append(int(sub[np.argmin(dist)]))
                axes.append(k)
            self.node_distance_m = owner_best[0]
        keep = [i for i, d in enumerate(dofs) if d not in set(fe.bc_local_owned.tolist())]
        self.local_dofs = np.array([dofs[i] for i in keep], dtype=np.int32)
        self.dof_axes = np.array([axes[i] for i in keep], dtype=int)
        self.owner = self.comm.allreduce(self.comm.rank if self.local_dofs.size else self.comm.size, op=MPI.MIN)
        if self.owner == self.comm.size:
            raise ValueError(f"contact {name!r}: the node at {point.tolist()} has no free displacement DOF")
        x_node = coords[self.local_dofs[0]] if self.comm.rank == self.owner else None
        self.x_node = self.comm.bcast(x_node, root=self.owner)
        self._mine, self._serial = self.comm.rank == self.owner, self.comm.size == 1
        self._axes_values = self.dof_axes.tolist()
        self.set_body_reference(np.zeros(fe.gdim))

    def set_body_reference(self, position_m) -> None:
        self.body_reference = np.asarray(position_m, dtype=float).copy()
        self._reference_values = self.body_reference.tolist()
        self._reference_gap = float(self.normal @ (self.x_node - self.body_reference))    # normal.(x - p_ref)

    def _node_values(self, arr: np.ndarray) -> np.ndarray:
        """The node's displacement-like vector from a local DOF array (owner), broadcast (gdim)."""
        out = np.zeros(self.fe.gdim)
        if self._mine:
            out[self.dof_axes] = arr[self.local_dofs]
        return out if self._serial else self.comm.bcast(out, root=self.owner)

    def penetration(self, u: np.ndarray, v: np.ndarray, body_position, body_velocity) -> tuple[float, float]:
        """(delta [m], d delta/dt [m/s]) for local arrays u, v and the body state. The gap is formed
        as normal.(x - p_ref) + normal.(u - dz) - R (small differences, no round-off of |x|)."""
        # in Python floats: a node's few components cost more as numpy calls than as arithmetic
        n_du = n_dv = 0.0
        if self._serial:        # the node's components as lists (zero on the axes it has no DOF of)
            node_u, node_v = [0.0] * len(self._normal_values), [0.0] * len(self._normal_values)
            for k, u_k, v_k in zip(self._axes_values, u[self.local_dofs].tolist(), v[self.local_dofs].tolist()):
                node_u[k], node_v[k] = u_k, v_k
        else:
            node_u, node_v = self._node_values(u).tolist(), self._node_values(v).tolist()
        for n_k, u_k, v_k, p_k, r_k, w_k in zip(self._normal_values, node_u, node_v, _values(body_position),
                                                self._reference_values, _values(body_velocity)):
            n_du += n_k * (u_k - (p_k - r_k))
            n_dv += n_k * (v_k - w_k)
        return -(self._reference_gap + n_du - self.radius_m), -n_dv

    def force(self, delta: float, rate: float) -> tuple[float, float, float]:
        """(F [N], dF/d delta [N/m], dF/d rate [N s/m]) of the Hertz spring + damper, F >= 0."""
        if delta <= 0.0:
            return 0.0, 0.0, 0.0
        root = math.sqrt(delta)
        f = self.stiffness * delta * root + self.damping * rate
        if f <= 0.0:
            return 0.0, 0.0, 0.0
        return float(f), 1.5 * self.stiffness * float(root), self.damping

    def elastic_energy_J(self, delta: float) -> float:
        return 0.4 * self.stiffness * max(delta, 0.0) ** 2.5

    # ------------------------------------------------------------ interaction protocol
    kind = "node"
    fe_coupled = True
    reads_fields = False          # reads system.u_mid, v_mid and states directly, never the shared fields

    def bind(self, system) -> None:
        rigid = system.rigid
        if self.body not in rigid.index:
            raise ValueError(f"contact {self.name!r} names unknown rigid body {self.body!r}")
        self.set_body_reference(rigid.body(self.body).position_m)
        first = self.fe.first_global
        mine = [(int(d + first), int(k)) for d, k in zip(self.local_dofs, self.dof_axes)]
        pairs = self.comm.bcast(mine, root=self.owner)
        self._S = np.array([system.contact_position[g] for g, _ in pairs], dtype=int)
        self._S_axes = np.array([k for _, k in pairs], dtype=int)
        self._normal_S = self.normal[self._S_axes]
        self._normal_S_outer = np.outer(self._normal_S, self._normal_S)
        self._body_dofs = rigid.dofs(self.body)

    def move_to_iterate(self, system) -> None:
        pass

    def _at_iterate(self, system) -> tuple[float, float, tuple[float, float, float]]:
        """(delta, rate, force(delta, rate)) at the system's mid-point fields, kept while its
        ``iterate_version`` stays (the residual, the tangent and the dissipation of one iterate)."""
        key = (system, getattr(system, "iterate_version", None))
        if key[1] is None or self._iterate_key != key:
            sl = self._body_dofs
            z, zd = system.rigid_mid_values() if key[1] is not None else (system.z_mid, system.zd_mid)
            delta, rate = self.penetration(system.u_mid, system.v_mid, z[sl], zd[sl])
            self._iterate_values = (delta, rate, self.force(delta, rate))
            self._iterate_key = key
        return self._iterate_values

    def _force_at_iterate(self, system):
        return self._at_iterate(system)[2]

    def _slip_map(self, system) -> tuple[np.ndarray, np.ndarray]:
        """(P, rates): P maps the rates xi' = (node velocity (gdim), body coordinate rates) at the
        evaluated iterate to the node's velocity relative to the sphere's surface point R n."""
        rigid, gdim = system.rigid, self.fe.gdim
        P = np.hstack([np.eye(3)[:, :gdim], -velocity_map(rigid, self.body, self.radius_m * pad3(self.normal))])
        rates = np.concatenate([self._node_values(system.v_mid), system.zd_mid[rigid.all_dofs(self.body)]])
        return P, rates

    def _friction_terms(self, system, tangent: bool):
        """With friction, in the unknowns xi = (node displacement (gdim), body coordinates): the
        force F on the node [N], the generalised forces P^T F and, with ``tangent``, the block
        d(-P^T F)/d xi_{n+1}; P maps xi rates to the slip velocity v_node - (v_body + omega x R n)."""
        gdim = self.fe.gdim
        f, k_f, c_f = self._force_at_iterate(system)
        n3 = pad3(self.normal)
        P, rates = self._slip_map(system)
        F = f * n3
        dF_ds, dF_dN = np.zeros((3, 3)), np.zeros(3)
        if f > 0.0:
            tangential = np.eye(3) - np.outer(n3, n3)
            F_t, dF_ds, dF_dN = friction_force(tangential @ (P @ rates), f, self.friction)
            F = F + F_t
            dF_ds = dF_ds @ tangential
        if not tangent:
            return F, P.T @ F, None
        D = np.zeros(P.shape[1])                   # d delta / d xi
        D[:gdim] = -self.normal
        D[gdim:2 * gdim] = self.normal
        dF = np.outer(n3 + dF_dN, (k_f + c_f * system.c_vel) * D) + system.c_vel * dF_ds @ P
        return F, P.T @ F, -(1 - system.scheme.alpha_f) * P.T @ dF

    def add_residual(self, system, rc_S, r_z, r):
        if self.friction is not None:
            gdim = self.fe.gdim
            F, generalised, _ = self._friction_terms(system, tangent=False)
            if r is not None and self.local_dofs.size:
                r.array_w[self.local_dofs] -= F[self.dof_axes]
            rc_S[self._S] -= F[self._S_axes]
            r_z[system.rigid.all_dofs(self.body)] -= generalised[gdim:]
            return -F[:gdim]
        f = self._at_iterate(system)[2][0]
        if f != 0.0:        # open: nothing to add
            if r is not None and self.local_dofs.size:
                r.array_w[self.local_dofs] -= f * self.normal[self.dof_axes]
            rc_S[self._S] -= f * self._normal_S
            r_z[self._body_dofs] += f * self.normal
        return -f * self.normal

    def add_tangent(self, system, Kss, B, L, Kzz) -> None:
        if self.friction is not None:
            gdim = self.fe.gdim
            _, _, J = self._friction_terms(system, tangent=True)
            node, S = self._S_axes, self._S                 # node components held as contact DOFs
            body = np.arange(system.rigid.size)[system.rigid.all_dofs(self.body)]
            Kss += _sparse_block(S, J[np.ix_(node, node)], system.contact_global.size)
            B[np.ix_(S, body)] += J[np.ix_(node, gdim + np.arange(body.size))]
            L[np.ix_(body, S)] += J[np.ix_(gdim + np.arange(body.size), node)]
            Kzz[np.ix_(body, body)] += J[gdim:, gdim:]
            return
        _, k_f, c_f = self._force_at_iterate(system)
        if k_f == 0.0 and c_f == 0.0:
            return      # open: no block
        block = _sparse_block(self._S, (1 - system.scheme.alpha_f) * (k_f + c_f * system.c_vel) * self._normal_S_outer,
                              system.contact_global.size)
        T = system.translation_S
        Kss += block
        sl = self._body_dofs
        B[:, sl] -= block @ T
        L[sl, :] -= T.T @ block
        Kzz[sl, sl] += T.T @ block @ T

    def status(self, system, state) -> tuple[bool, float]:
        sl = system.rigid.dofs(self.body)
        delta, rate = self.penetration(state.u, state.v, state.z[sl], state.zd[sl])
        return delta > 0, (-delta / rate if delta <= 0 and rate > 0 else math.inf)

    def stored_energy_J(self, system, state) -> float:
        sl = system.rigid.dofs(self.body)
        return self.elastic_energy_J(self.penetration(state.u, state.v, state.z[sl], state.zd[sl])[0])

    def dissipation_power_W(self, system) -> float:
        """Power dissipated by the damper and friction [W] at the evaluated iterate."""
        delta, rate, (f, _, _) = self._at_iterate(system)
        if delta <= 0.0:
            return 0.0
        power = (f - self.stiffness * delta * math.sqrt(delta)) * rate
        if self.friction is not None and f > 0.0:
            n3 = pad3(self.normal)
            P, rates = self._slip_map(system)
            slip = (np.eye(3) - np.outer(n3, n3)) @ (P @ rates)
            power -= float(friction_force(slip, f, self.friction)[0] @ slip)
        return float(power)


def _values(x) -> list:
    """A few coordinates as a list of floats (a list as it is)."""
    return x if isinstance(x, list) else np.asarray(x, dtype=float).tolist()


def _sparse_block(positions: np.ndarray, values: np.ndarray, s_count: int):
    """The s x s matrix holding ``values`` at rows and columns ``positions`` (contact DOFs): sparse, or dense
    for a few contact DOFs (app.transient.active_set.DENSE_MAX)."""
    if s_count <= DENSE_MAX:
        block = np.zeros((s_count, s_count))
        block[np.ix_(positions, positions)] = values
        return block
    rows = np.repeat(positions, positions.size)
    cols = np.tile(positions, positions.size)
    values = np.asarray(values, dtype=float).reshape(-1)
    return scipy.sparse.csr_matrix((values, (rows, cols)), shape=(s_count, s_count))
