"""Rigid bodies: translations and rotations about named axes.

A body's generalised coordinates are its reference-point position z [m] (the reference point of
its contact shapes, gdim components in the mesh axes) followed by one angle [rad] per declared
rotation axis: in 3D any of ``"x"``, ``"y"``, ``"z"``; in 2D (plane strain) the one in-plane
rotation ``"plane"`` (counter-clockwise from the first mesh axis to the second). Every
coordinate is free, prescribed as a function of time (a wall, a shaker table, a rotor spun at a
constant rate) or fixed, and integrated with the same generalized-alpha scheme as the FE part, so
the coupled step stays consistent.

Angles are about fixed global axes through the reference point, with a diagonal inertia: exact
for a body spinning about one axis (the motor's rotor), gyroscopic coupling between several
rotation axes is neglected. Interactions use the angular velocity (slip omega x r, torque r x F);
obstacle shapes attached to a rotating body must be invariant under its rotations (a body of
revolution about its own axis), which the interactions check.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

PrescribedMotion = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]

ROTATION_AXES_3D = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
ROTATION_AXES_2D = {"plane": (0.0, 0.0, 1.0)}


def rotation_axis_vectors(names, gdim: int) -> np.ndarray:
    """(n_rot, 3) unit axes of the named rotations (2D vectors are embedded as (x0, x1, 0))."""
    table = ROTATION_AXES_2D if gdim == 2 else ROTATION_AXES_3D
    for name in names:
        if name not in table:
            raise ValueError(f"rotation axis {name!r} is not one of {', '.join(table)} in {gdim}D")
    return np.array([table[n] for n in names], dtype=float).reshape(-1, 3)


@dataclass
class RigidBody:
    """A rigid body.

    ``prescribed`` (optional) returns (coordinates, rates, accelerations) at time t for all the
    body's coordinates (translations then angles); only the entries flagged in ``prescribed_axes``
    are used; a body with every coordinate prescribed and no motion is a fixed obstacle.
    ``applied_force_N`` returns the external force vector at time t (without gravity, which is
    ``mass_kg * gravity_m_per_s2``), ``applied_torque_N_m`` the torques about the rotation axes.
    ``brake_N_m_s_per_rad`` (one per rotation axis, default 0) is a viscous brake: a torque
    -brake * angular velocity about that axis, on top of the applied torque (a load that grows
    with speed; constant torque T against a brake c gives the steady speed T / c)."""

    name: str
    mass_kg: float
    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    gravity_m_per_s2: np.ndarray
    applied_force_N: Callable[[float], np.ndarray] | None = None
    prescribed_axes: tuple[bool, ...] | None = None
    prescribed: PrescribedMotion | None = None
    rotation_axes: tuple[str, ...] = ()
    inertia_kg_m2: tuple[float, ...] = ()
    angle_rad: tuple[float, ...] | None = None
    angular_velocity_rad_per_s: tuple[float, ...] | None = None
    applied_torque_N_m: Callable[[float], np.ndarray] | None = None
    brake_N_m_s_per_rad: tuple[float, ...] | None = None
    free_axes_mask: np.ndarray = field(init=False)

    def __post_init__(self):
        self.position_m = np.asarray(self.position_m, dtype=float)
        self.velocity_m_per_s = np.asarray(self.velocity_m_per_s, dtype=float)
        self.gravity_m_per_s2 = np.asarray(self.gravity_m_per_s2, dtype=float)
        gdim = self.position_m.size
        if self.velocity_m_per_s.size != gdim or self.gravity_m_per_s2.size != gdim:
            raise ValueError(f"rigid body {self.name!r}: position, velocity and gravity need {gdim} components")
        self.rotation_axes = tuple(self.rotation_axes)
        self.axis_vectors = rotation_axis_vectors(self.rotation_axes, gdim)
        n_rot = len(self.rotation_axes)
        self.inertia_kg_m2 = np.asarray(self.inertia_kg_m2 if n_rot else (), dtype=float).reshape(-1)
        self.angle_rad = np.asarray(self.angle_rad if self.angle_rad is not None else [0.0] * n_rot, dtype=float)
        self.angular_velocity_rad_per_s = np.asarray(
            self.angular_velocity_rad_per_s if self.angular_velocity_rad_per_s is not None else [0.0] * n_rot,
            dtype=float)
        self.brake_N_m_s_per_rad = np.asarray(
            self.brake_N_m_s_per_rad if self.brake_N_m_s_per_rad is not None else [0.0] * n_rot, dtype=float)
        if np.any(self.brake_N_m_s_per_rad < 0):
            raise ValueError(f"rigid body {self.name!r}: a brake must be >= 0")
        for label, arr in (("inertia_kg_m2", self.inertia_kg_m2), ("angle_rad", self.angle_rad),
                           ("angular_velocity_rad_per_s", self.angular_velocity_rad_per_s),
                           ("brake_N_m_s_per_rad", self.brake_N_m_s_per_rad)):
            if arr.size != n_rot:
                raise ValueError(f"rigid body {self.name!r}: {label} needs {n_rot} entries (one per rotation axis)")
        n = self.n_dofs
        axes = self.prescribed_axes if self.prescribed_axes is not None else (False,) * n
        if len(axes) != n:
            raise ValueError(f"rigid body {self.name!r}: prescribed_axes needs {n} entries")
        if any(axes) and self.prescribed is None:
            self.prescribed = _hold(self.coordinates())
        self.free_axes_mask = ~np.asarray(axes, dtype=bool)
        if self.free_axes_mask[:gdim].any() and not self.mass_kg > 0:
            raise ValueError(f"rigid body {self.name!r}: a body with free axes needs a positive mass")
        free_rotations = self.free_axes_mask[gdim:]
        if n_rot and free_rotations.any() and not np.all(self.inertia_kg_m2[free_rotations] > 0):
            raise ValueError(f"rigid body {self.name!r}: a free rotation needs a positive inertia")

    @property
    def gdim(self) -> int:
        return self.position_m.size

    @property
    def n_dofs(self) -> int:
        return self.position_m.size + len(self.rotation_axes)

    def coordinates(self) -> np.ndarray:
        return np.concatenate([self.position_m, self.angle_rad])

    def rates(self) -> np.ndarray:
        return np.concatenate([self.velocity_m_per_s, self.angular_velocity_rad_per_s])

    def inertia_diagonal(self) -> np.ndarray:
        return np.concatenate([np.full(self.gdim, float(self.mass_kg)), self.inertia_kg_m2])

    def damping_diagonal(self) -> np.ndarray:
        """Viscous coefficients per coordinate: 0 on the translations, the brakes [N m s/rad] on
        the angles (the load is -damping * rate)."""
        return np.concatenate([np.zeros(self.gdim), self.brake_N_m_s_per_rad])

    def external_force_N(self, t: float) -> np.ndarray:
        """Generalised external load: force [N] (incl. gravity), then torques [N m]; without the
        brake, which depends on the rate (:meth:`RigidSet.brake_force_N`)."""
        force = self.mass_kg * self.gravity_m_per_s2
        if self.applied_force_N is not None:
            force = force + np.asarray(self.applied_force_N(t), dtype=float)
        torque = np.zeros(len(self.rotation_axes))
        if self.applied_torque_N_m is not None:
            torque = torque + np.asarray(self.applied_torque_N_m(t), dtype=float)
        return np.concatenate([force, torque])


def fixed_body(name: str, position_m, gdim: int | None = None) -> RigidBody:
    """An immovable obstacle (wall, ground) at ``position_m``."""
    position = np.asarray(position_m, dtype=float)
    zeros = np.zeros_like(position)
    return RigidBody(name, 0.0, position, zeros, zeros, prescribed_axes=(True,) * position.size)


def harmonic_motion(rest_position_m, amplitude_m, frequency_Hz: float) -> PrescribedMotion:
    """z(t) = z0 + A sin(2 pi f t), for shaker-table style obstacles."""
    z0 = np.asarray(rest_position_m, dtype=float)
    amp = np.asarray(amplitude_m, dtype=float)
    w = 2 * np.pi * frequency_Hz

    def motion(t: float):
        return z0 + amp * np.sin(w * t), amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t)

    return motion


def constant_rate_motion(start, rate) -> PrescribedMotion:
    """q(t) = q0 + rate t for every coordinate (a belt at constant speed, a rotor at constant spin)."""
    q0 = np.asarray(start, dtype=float)
    qd = np.asarray(rate, dtype=float)
    if not qd.any():
        return _hold(q0)
    zeros = np.zeros_like(q0)
    return lambda t: (q0 + qd * t, qd, zeros)


def _hold(position: np.ndarray) -> PrescribedMotion:
    zeros = np.zeros_like(position)

    def hold(t: float):
        return position, zeros, zeros

    hold.constant = True        # the same values at every t (RigidSet.apply_prescribed keeps them)
    return hold


class RigidSet:
    """All rigid bodies of a model, with their coordinates packed as one vector (body-major: each
    body's translations, then its angles)."""

    def __init__(self, bodies: list[RigidBody]):
        names = [b.name for b in bodies]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate rigid body names in {names}")
        gdims = {b.gdim for b in bodies}
        if len(gdims) > 1:
            raise ValueError("all rigid bodies need the same number of components")
        self.bodies = list(bodies)
        self.gdim = gdims.pop() if gdims else 0
        self.index = {b.name: i for i, b in enumerate(bodies)}
        sizes = [b.n_dofs for b in bodies]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int) if bodies else np.zeros(1, int)
        self.size = int(self.offsets[-1])
        self.mass_diagonal = (np.concatenate([b.inertia_diagonal() for b in bodies]) if bodies
                              else np.zeros(0))
        self.free_mask = np.concatenate([b.free_axes_mask for b in bodies]) if bodies else np.zeros(0, bool)
        # brakes act on free coordinates only (a prescribed one is not loaded by anything)
        damping = [b.damping_diagonal() for b in bodies]
        self.damping_diagonal = np.concatenate(damping) * self.free_mask if bodies else np.zeros(0)
        # each body's packed coordinates and prescribed axes (fixed at construction), for apply_prescribed
        self._prescribed_layout = [(b, np.arange(self.size)[self.all_dofs(b.name)][~b.free_axes_mask],
                                    ~b.free_axes_mask) for b in self.bodies]
        # no body has a time-dependent applied force or torque (gravity only): external_force_N keeps one array
        self._loads_constant = all(b.applied_force_N is None and b.applied_torque_N_m is None for b in self.bodies)
        self._constant_load = None
        self._held = {}     # body -> (its constant motion, the prescribed values)

    def body(self, name: str) -> RigidBody:
        return self.bodies[self.index[name]]

    def dofs(self, name: str) -> slice:
        """The body's translations in the packed vector."""
        start = self.offsets[self.index[name]]
        return slice(start, start + self.gdim)

    def rotation_dofs(self, name: str) -> slice:
        """The body's angles in the packed vector (empty if it does not rotate)."""
        i = self.index[name]
        return slice(self.offsets[i] + self.gdim, self.offsets[i + 1])

    def all_dofs(self, name: str) -> slice:
        i = self.index[name]
        return slice(self.offsets[i], self.offsets[i + 1])

    def angular_velocity(self, name: str, rates: np.ndarray) -> np.ndarray:
        """The body's angular velocity as a 3-vector [rad/s] from packed rates."""
        return rates[self.rotation_dofs(name)] @ self.body(name).axis_vectors

    @property
    def rotating(self) -> bool:
        return any(b.rotation_axes for b in self.bodies)

    def initial_state(self, t0: float = 0.0):
        z = np.concatenate([b.coordinates() for b in self.bodies]) if self.bodies else np.zeros(0)
        v = np.concatenate([b.rates() for b in self.bodies]) if self.bodies else np.zeros(0)
        a = np.zeros_like(z)
        for b in self.bodies:
            sl = self.all_dofs(b.name)
            inertia = b.inertia_diagonal()
            loaded = inertia > 0
            load = b.external_force_N(t0) - b.damping_diagonal() * v[sl]
            a[sl][loaded] = load[loaded] / inertia[loaded]
        self.apply_prescribed(t0, z, v, a)
        return z, v, a

    def brake_force_N(self, rates: np.ndarray) -> np.ndarray:
        """Generalised brake load (torques about the free axes) [N m] at the packed ``rates``."""
        return -self.damping_diagonal * rates

    def external_force_N(self, t: float) -> np.ndarray:
        if not self.bodies:
            return np.zeros(0)
        if self._loads_constant:     # gravity only: the same array at every t (a copy: callers may write it)
            if self._constant_load is None:
                self._constant_load = np.concatenate([b.external_force_N(t) for b in self.bodies])
            return self._constant_load.copy()
        return np.concatenate([b.external_force_N(t) for b in self.bodies])

    def apply_prescribed(self, t: float, z, v=None, a=None) -> None:
        """Overwrite prescribed components of (z, v, a) with their values at time t."""
        for i, (b, index, fixed) in enumerate(self._prescribed_layout):
            motion = b.prescribed
            if motion is None or not index.size:
                continue
            held = self._held.get(i)
            if held is None or held[0] is not motion:
                held = (motion, *(np.asarray(x)[fixed] for x in motion(t)))
                if getattr(motion, "constant", False):
                    self._held[i] = held
            _, pos, vel, acc = held
            z[index] = pos
            if v is not None:
                v[index] = vel
            if a is not None:
                a[index] = acc
