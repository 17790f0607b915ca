"""Strain and electric field in 3D Voigt form for 3D, axisymmetric and plane-strain models.

Every model kind is expressed with the full 3D IEEE Voigt order (xx, yy, zz, yz, xz, xy; shear
as engineering strain) so one set of 6x6/3x6/3x3 material tensors serves all kinds:

- ``"3d"``: coordinates (x, y, z).
- ``"axisymmetric"``: mesh coordinates (r, z) map to 3D axes 1 = r, 2 = theta, 3 = z; no torsion.
- ``"plane_strain"``: mesh coordinates (x, z) map to 3D axes 1 and 3; axis 2 is out of plane.
"""

from __future__ import annotations

import math

import ufl
from ufl.domain import extract_unique_domain

MODEL_KINDS = ("3d", "axisymmetric", "plane_strain")


def strain_voigt(u, kind: str):
    """Engineering strain 6-vector of displacement ``u`` [m] (dimensionless)."""
    if kind == "3d":
        g = ufl.grad(u)
        return ufl.as_vector(
            [g[0, 0], g[1, 1], g[2, 2], g[1, 2] + g[2, 1], g[0, 2] + g[2, 0], g[0, 1] + g[1, 0]]
        )
    g = ufl.grad(u)
    if kind == "axisymmetric":
        r = ufl.SpatialCoordinate(extract_unique_domain(u))[0]
        return ufl.as_vector([g[0, 0], u[0] / r, g[1, 1], 0, g[0, 1] + g[1, 0], 0])
    if kind == "plane_strain":
        return ufl.as_vector([g[0, 0], 0, g[1, 1], 0, g[0, 1] + g[1, 0], 0])
    raise ValueError(f"unknown model kind {kind!r}")


def electric_field(phi, kind: str):
    """E = -grad(phi) as a 3D vector [V/m] for electric potential ``phi`` [V]."""
    g = ufl.grad(phi)
    if kind == "3d":
        return -g
    if kind in ("axisymmetric", "plane_strain"):
        return ufl.as_vector([-g[0], 0, -g[1]])
    raise ValueError(f"unknown model kind {kind!r}")


def displacement_3d(u, kind: str):
    """Displacement as a 3D vector in the model's 3D axes (hoop/out-of-plane component 0)."""
    if kind == "3d":
        return u
    return ufl.as_vector([u[0], 0, u[1]])


def volume_weight(mesh, kind: str, thickness_m: float = 1.0):
    """Factor turning the mesh measure into physical volume [m^3 per mesh unit]: 2*pi*r for
    axisymmetric (integrals are over the whole body of revolution), the out-of-plane thickness
    for plane strain, 1 in 3D."""
    if kind == "axisymmetric":
        return 2 * math.pi * ufl.SpatialCoordinate(mesh)[0]
    if kind == "plane_strain":
        return thickness_m
    return 1.0
