"""The rigid bodies drawn with their shapes for the field output (ParaView, meshio), the same in every tier
that writes fields (FE and modal): one triangle mesh of all bodies, built once from the case's body and
contact data, and each output's displacement [m] of its vertices from the bodies' coordinates z (translations
then angles, the packing of app/transient/rigid.py and app/contact/records.py).

Every shape is a body of revolution about an axis through the body's reference point, given by a profile
(rho, s): rho >= 0 the distance from the axis, s the position along it. In 3D the profile is revolved into a
closed surface; in 2D the section is drawn in the mesh plane (x0, x1, 0): the half on the r >= 0 side for a
shape on the axis of an axisymmetric model (as the FE section is drawn), both halves otherwise. The shapes:

- a sphere (a ``sphere`` surface contact, or a ``node`` contact: Hertz against a sphere) of its radius,
  centred at the reference point;
- a cone (a ``cone`` surface contact, the motor's rotor): the conical face of radius ``radius_m`` at the
  reference point opening along ``axis`` at ``half_angle_deg``, drawn as a disc whose rim is that face over
  +-radius/6 along the axis, closed by flat faces;
- a plane (a ``plane`` surface contact) and a body that is only the ``lower`` body of ``point`` contacts (the
  drill's rock): a slab below its reference point (on the side away from the normal or the contact's
  direction), a finite patch sized from the scene: radius half the largest extent of the FE mesh, depth a
  quarter of that;
- a body that is the ``upper`` body of a ``point`` contact and has no shape of its own (the drill stem): a rod
  from its reference point back along the contact's direction to the lower body (touch_distance_m less the
  lower body's sphere radius), as thick as a sphere resting on it (else a twentieth of its length);
- any other body: a small sphere (a fiftieth of the scene) marking its reference point.

These sizes only draw the bodies: the contact laws use the contact data alone. A body's rotations turn its
mesh about its axes through the reference point (a body of revolution about its spin axis looks the same,
so the surfaces carry a ``sector`` cell value in alternating stripes that shows the spin).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: segments of a drawn circle (3D revolution) and of a sphere's meridian
AROUND = 48
MERIDIAN = 24
#: stripes of the ``sector`` cell value round a revolved body
STRIPES = 8

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0), "plane": (0.0, 0.0, 1.0)}


@dataclass
class _Shape:
    kind: str                   # sphere, cone, slab, rod, marker
    axis: np.ndarray            # 3-vector, unit
    profile: np.ndarray         # (k, 2): (rho, s), from the axis round to the axis, s non-decreasing


def _unit3(v, gdim: int) -> np.ndarray:
    out = np.zeros(3)
    v = np.asarray(v, dtype=float).ravel()[:3]
    out[:v.size] = v
    n = np.linalg.norm(out)
    return out / n if n > 0 else np.array([0.0, 1.0, 0.0] if gdim == 2 else [0.0, 0.0, 1.0])


def _sphere(radius: float) -> np.ndarray:
    phi = np.linspace(0.0, np.pi, MERIDIAN + 1)
    profile = np.column_stack([radius * np.sin(phi), -radius * np.cos(phi)])
    profile[[0, -1], 0] = 0.0
    return profile


def _box(radius: float, s0: float, s1: float) -> np.ndarray:
    return np.array([[0.0, s0], [radius, s0], [radius, s1], [0.0, s1]])


def sphere_shape(radius_m: float, axis=(0.0, 0.0, 1.0)) -> _Shape:
    """A sphere of ``radius_m`` centred at its body's reference point."""
    return _Shape("sphere", _unit3(axis, 3), _sphere(radius_m))


def cylinder_shape(radius_m: float, from_m: float, to_m: float, axis=(0.0, 0.0, 1.0), kind: str = "rod") -> _Shape:
    """A closed cylinder of ``radius_m`` along the unit ``axis`` from ``from_m`` to ``to_m`` (from_m < to_m) of
    the body's reference point (``kind`` "slab" for a wide flat one, "rod" otherwise: the same drawing)."""
    return _Shape(kind, _unit3(axis, 3), _box(radius_m, from_m, to_m))


def body_shapes(transient, scene_size_m: float) -> dict[str, list[_Shape]]:
    """Shapes of each body of the ``[transient]`` section (name -> list of shapes), see the module's rules;
    ``scene_size_m``: the FE mesh's largest extent."""
    gdim = len(transient.bodies[0].position_m) if transient.bodies else 3
    default_axis = _unit3([0.0, 1.0] if gdim == 2 else [0.0, 0.0, 1.0], gdim)
    shapes: dict[str, list[_Shape]] = {b.name: [] for b in transient.bodies}
    spheres: dict[str, float] = {}
    patch = max(scene_size_m, 1e-12) / 2
    for c in transient.contacts:
        if c.kind == "node" or (c.kind == "surface" and c.shape == "sphere"):
            axis = _unit3(c.normal, gdim) if c.normal is not None else default_axis
            shapes[c.body].append(_Shape("sphere", axis, _sphere(c.radius_m)))
            spheres[c.body] = max(spheres.get(c.body, 0.0), c.radius_m)
        elif c.kind == "surface" and c.shape == "cone":
            h = c.radius_m / 6
            grow = np.tan(np.radians(c.half_angle_deg))
            profile = np.array([[0.0, -h], [max(c.radius_m - h * grow, 0.0), -h], [c.radius_m + h * grow, h],
                                [0.0, h]])
            shapes[c.body].append(_Shape("cone", _unit3(c.axis, gdim), profile))
        elif c.kind == "surface":            # a plane: the obstacle fills the side away from its normal
            shapes[c.body].append(_Shape("slab", _unit3(c.normal, gdim), _box(patch, -patch / 2, 0.0)))
    for c in transient.contacts:
        if c.kind != "point" or shapes[c.upper]:
            continue
        length = c.touch_distance_m - spheres.get(c.lower, 0.0)
        if length > 0:
            resting = [spheres[p.upper] for p in transient.contacts
                       if p.kind == "point" and p.lower == c.upper and p.upper in spheres]
            radius = max(resting) if resting else length / 20
            shapes[c.upper].append(_Shape("rod", _unit3(c.direction, gdim), _box(radius, -length, 0.0)))
    for c in transient.contacts:
        if c.kind == "point" and not shapes[c.lower]:
            shapes[c.lower].append(_Shape("slab", _unit3(c.direction, gdim), _box(patch, -patch / 2, 0.0)))
    for found in shapes.values():
        if not found:
            found.append(_Shape("marker", default_axis, _sphere(scene_size_m / 50)))
    return shapes


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``axis`` and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def _revolve(shape: _Shape, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed triangle surface of the profile revolved about the shape's axis: (points, triangles, sector)."""
    e1, e2 = _frame(shape.axis)
    theta = 2 * np.pi * np.arange(AROUND) / AROUND
    points, index = [], []
    for rho, s in shape.profile:
        centre = reference + s * shape.axis
        if rho == 0.0:              # a pole: one point
            index.append([len(points)] * AROUND)
            points.append(centre)
        else:
            index.append(list(range(len(points), len(points) + AROUND)))
            points.extend(centre + rho * (np.cos(t) * e1 + np.sin(t) * e2) for t in theta)
    triangles, sector = [], []
    for i in range(len(index) - 1):
        for j in range(AROUND):
            k = (j + 1) % AROUND
            a, b, c, d = index[i][j], index[i + 1][j], index[i + 1][k], index[i][k]
            for tri in ((a, b, c), (a, c, d)):
                if len(set(tri)) == 3:
                    triangles.append(tri)
                    sector.append((j * STRIPES // AROUND) % 2)
    return np.asarray(points), np.asarray(triangles, dtype=np.int64), np.asarray(sector, dtype=np.int32)


def _section(shape: _Shape, reference: np.ndarray, half: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The profile's section in the mesh plane: the region between the axis and the profile, one side (half)
    or both, as triangles of quads between consecutive profile points."""
    across = np.array([shape.axis[1], -shape.axis[0], 0.0])        # in plane, perpendicular to the axis
    if half and across[0] < 0:
        across = -across                                            # the r >= 0 side
    points, triangles = [], []
    for side in ((1.0,) if half else (1.0, -1.0)):
        base = len(points)
        for rho, s in shape.profile:
            points.append(reference + s * shape.axis)
            points.append(reference + s * shape.axis + side * rho * across)
        for i in range(len(shape.profile) - 1):
            a, b, c, d = (base + 2 * i, base + 2 * i + 1, base + 2 * i + 3, base + 2 * i + 2)
            for tri in ((a, b, c), (a, c, d)):
                p = np.asarray([points[t] for t in tri])
                if np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) > 1e-12 * max(np.abs(p).max(), 1e-30) ** 2:
                    triangles.append(tri)
    return np.asarray(points), np.asarray(triangles, dtype=np.int64), np.zeros(len(triangles), dtype=np.int32)


class BodyMeshes:
    """All rigid bodies as one triangle mesh at their start (``points`` (N, 3) [m], ``triangles``, per cell
    ``body`` (index into ``names``) and ``sector``), and ``displacement(z)``: each vertex's displacement [m]
    from the start for the packed body coordinates z. ``slices``: each body's coordinates in z (translations,
    then one angle per rotation)."""

    def __init__(self, transient, model_kind: str, slices: dict[str, slice], scene_size_m: float):
        bodies = transient.bodies
        gdim = len(bodies[0].position_m) if bodies else 3
        shapes = body_shapes(transient, scene_size_m)
        self._build([(b.name, b.position_m, [(r.axis, r.angle_rad) for r in b.rotations], shapes[b.name])
                     for b in bodies], gdim, model_kind, slices)

    @classmethod
    def from_shapes(cls, bodies, gdim: int, model_kind: str, slices: dict[str, slice]) -> BodyMeshes:
        """Bodies given by their shapes: ``bodies`` a list of (name, reference position (gdim) [m], rotations as
        [(axis name, start angle [rad])], [shapes]), shapes from :func:`sphere_shape` and :func:`cylinder_shape`
        (the lumped tier's drill, which has no [transient] section)."""
        meshes = cls.__new__(cls)
        meshes._build(bodies, gdim, model_kind, slices)
        return meshes

    def _build(self, bodies, gdim: int, model_kind: str, slices: dict[str, slice]) -> None:
        self.names = [name for name, *_ in bodies]
        self.gdim = gdim
        points, triangles, body, sector = [], [], [], []
        self._vertices, self._start, self._axes, self._slices, self._angles = [], [], [], [], []
        n = 0
        for index, (name, position, rotations, shapes) in enumerate(bodies):
            reference = np.zeros(3)
            reference[:self.gdim] = position
            first = n
            for shape in shapes:
                if self.gdim == 3:
                    p, t, s = _revolve(shape, reference)
                else:
                    half = model_kind == "axisymmetric" and abs(reference[0]) < 1e-15 and abs(shape.axis[0]) < 1e-12
                    p, t, s = _section(shape, reference, half)
                points.append(p)
                triangles.append(t + n)
                body.append(np.full(len(t), index, dtype=np.int32))
                sector.append(s)
                n += len(p)
            self._vertices.append(slice(first, n))
            self._start.append((reference, np.array([angle for _, angle in rotations], dtype=float)))
            self._axes.append(np.array([_AXES[axis] for axis, _ in rotations], dtype=float).reshape(-1, 3))
            self._slices.append(slices[name])
        self.points = np.concatenate(points) if points else np.zeros((0, 3))
        self.triangles = np.concatenate(triangles) if triangles else np.zeros((0, 3), dtype=np.int64)
        self.body = np.concatenate(body) if body else np.zeros(0, dtype=np.int32)
        self.sector = np.concatenate(sector) if sector else np.zeros(0, dtype=np.int32)

    def displacement(self, z) -> np.ndarray:
        """(N, 3) displacement [m] of every vertex at the packed coordinates ``z`` (None: the start)."""
        if z is None:
            return np.zeros_like(self.points)
        return self.displacements(np.asarray(z, dtype=float)[None])[0]

    def displacements(self, z: np.ndarray) -> np.ndarray:
        """(frames, N, 3) displacements [m] of every vertex at each row of the packed coordinates ``z`` (frames,
        coordinates): all the frames at once (a batch of field frames)."""
        z = np.asarray(z, dtype=float)
        frames = z.shape[0]
        out = np.zeros((frames, *self.points.shape))
        for vertices, (reference, angle0), axes, sl in zip(self._vertices, self._start, self._axes, self._slices):
            q = z[:, sl]
            position = np.zeros((frames, 3))
            position[:, :self.gdim] = q[:, :self.gdim]
            rotation = np.broadcast_to(np.eye(3), (frames, 3, 3))
            for axis, angle in zip(axes, (q[:, self.gdim:] - angle0).T):
                rotation = _rotation(axis, angle) @ rotation
            local = self.points[vertices] - reference
            out[:, vertices] = position[:, None, :] + local @ rotation.transpose(0, 2, 1) - self.points[vertices]
        return out


def _rotation(axis: np.ndarray, angle) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` [rad] about the unit ``axis``; (frames, 3, 3) for (frames,) angles."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    angle = np.asarray(angle, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)
