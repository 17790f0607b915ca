"""Rigid bodies with translational DOFs.

A body moves as a point mass: position z [m] (the reference point of its contact shapes), velocity
and acceleration, in the model's mesh axes (gdim components). Any component can be prescribed as
a function of time (a wall, the ground, a shaker table); the others are free and integrated with
the same generalized-alpha scheme as the FE part, so the coupled step stays consistent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

PrescribedMotion = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass
class RigidBody:
    """A translating rigid body.

    ``prescribed`` (optional) returns (position, velocity, acceleration) at time t for the
    components flagged in ``prescribed_axes``; a body with every axis prescribed and no motion is
    a fixed obstacle. ``applied_force_N`` returns the external force vector at time t (without
    gravity, which is ``mass_kg * gravity_m_per_s2``)."""

    name: str
    mass_kg: float
    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    gravity_m_per_s2: np.ndarray
    applied_force_N: Callable[[float], np.ndarray] | None = None
    prescribed_axes: tuple[bool, ...] | None = None
    prescribed: PrescribedMotion | None = None
    free_axes_mask: np.ndarray = field(init=False)

    def __post_init__(self):
        self.position_m = np.asarray(self.position_m, dtype=float)
        self.velocity_m_per_s = np.asarray(self.velocity_m_per_s, dtype=float)
        self.gravity_m_per_s2 = np.asarray(self.gravity_m_per_s2, dtype=float)
        gdim = self.position_m.size
        if self.velocity_m_per_s.size != gdim or self.gravity_m_per_s2.size != gdim:
            raise ValueError(f"rigid body {self.name!r}: position, velocity and gravity need {gdim} components")
        axes = self.prescribed_axes if self.prescribed_axes is not None else (False,) * gdim
        if len(axes) != gdim:
            raise ValueError(f"rigid body {self.name!r}: prescribed_axes needs {gdim} entries")
        if any(axes) and self.prescribed is None:
            self.prescribed = _hold(self.position_m.copy())
        self.free_axes_mask = ~np.asarray(axes, dtype=bool)
        if self.free_axes_mask.any() and not self.mass_kg > 0:
            raise ValueError(f"rigid body {self.name!r}: a body with free axes needs a positive mass")

    @property
    def gdim(self) -> int:
        return self.position_m.size

    def external_force_N(self, t: float) -> np.ndarray:
        force = self.mass_kg * self.gravity_m_per_s2
        if self.applied_force_N is not None:
            force = force + np.asarray(self.applied_force_N(t), dtype=float)
        return force


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


def _hold(position: np.ndarray) -> PrescribedMotion:
    zeros = np.zeros_like(position)
    return lambda t: (position, zeros, zeros)


class RigidSet:
    """All rigid bodies of a model, with their DOFs packed as one vector (body-major)."""

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
        self.size = self.gdim * len(bodies)
        self.mass_diagonal = np.repeat([b.mass_kg for b in bodies], self.gdim).astype(float)
        self.free_mask = np.concatenate([b.free_axes_mask for b in bodies]) if bodies else np.zeros(0, bool)

    def dofs(self, name: str) -> slice:
        i = self.index[name]
        return slice(i * self.gdim, (i + 1) * self.gdim)

    def initial_state(self, t0: float = 0.0):
        z = np.concatenate([b.position_m for b in self.bodies]) if self.bodies else np.zeros(0)
        v = np.concatenate([b.velocity_m_per_s for b in self.bodies]) if self.bodies else np.zeros(0)
        a = np.zeros_like(z)
        for i, b in enumerate(self.bodies):
            if b.mass_kg > 0:
                a[i * self.gdim:(i + 1) * self.gdim] = b.external_force_N(t0) / b.mass_kg
        self.apply_prescribed(t0, z, v, a)
        return z, v, a

    def external_force_N(self, t: float) -> np.ndarray:
        if not self.bodies:
            return np.zeros(0)
        return np.concatenate([b.external_force_N(t) for b in self.bodies])

    def apply_prescribed(self, t: float, z, v=None, a=None) -> None:
        """Overwrite prescribed components of (z, v, a) with their values at time t."""
        for i, b in enumerate(self.bodies):
            if b.prescribed is None:
                continue
            pos, vel, acc = b.prescribed(t)
            sl = slice(i * self.gdim, (i + 1) * self.gdim)
            fixed = ~b.free_axes_mask
            z[sl][fixed] = np.asarray(pos)[fixed]
            if v is not None:
                v[sl][fixed] = np.asarray(vel)[fixed]
            if a is not None:
                a[sl][fixed] = np.asarray(acc)[fixed]
