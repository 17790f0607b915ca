"""Strain and electric field in 3D Voigt form for 3D, axisymmetric, plane-strain and
Fourier-harmonic models.

Every model kind is expressed with the full 3D IEEE Voigt order (xx, yy, zz, yz, xz, xy; shear
as engineering strain) so one set of 6x6/3x6/3x3 material tensors serves all kinds:

- ``"3d"``: coordinates (x, y, z).
- ``"axisymmetric"``: mesh coordinates (r, z) map to 3D axes 1 = r, 2 = theta, 3 = z; no torsion.
- ``"plane_strain"``: mesh coordinates (x, z) map to 3D axes 1 and 3; axis 2 is out of plane.
- :class:`Fourier` (case kind ``"fourier"``): a body of revolution about z meshed in (r, z), whose
  fields are one circumferential order n, exactly in theta (the general-axisymmetric element):
  u_r = U_r(r, z) cos n theta, u_theta = U_theta(r, z) sin n theta, u_z = U_z(r, z) cos n theta,
  phi = Phi(r, z) cos n theta. The unknowns are the amplitudes U = (U_r, U_theta, U_z) (3D axes
  1 = r, 2 = theta, 3 = z) and Phi. Strains and fields below are the amplitudes of their cos n theta
  (rr, theta-theta, zz, rz; E_r, E_z) and sin n theta (theta-z, r-theta; E_theta) parts. With a material
  whose axes are r, theta, z (isotropic, or poled along r or z) no cos part couples to a sin part,
  and the integral over theta of every product is pi (2 pi for n = 0) times the product of the
  amplitudes: the volume weight is pi r (2 pi r for n = 0), and the (r, z) forms give the
  energies of the whole body. For n = 0 the same formulas give the axisymmetric model plus its
  torsion (u_theta = U_theta).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import ufl
from ufl.domain import extract_unique_domain

MODEL_KINDS = ("3d", "axisymmetric", "plane_strain", "fourier")


@dataclass(frozen=True)
class Fourier:
    """Kinematics of a Fourier-harmonic model of circumferential order ``order`` (n >= 0)."""

    order: int

    def __post_init__(self):
        if self.order < 0:
            raise ValueError(f"circumferential order must be >= 0, got {self.order}")


def kinematics(kind: str, order: int | None = None):
    """The kinematics object the forms take: ``kind`` itself, or :class:`Fourier` for ``"fourier"``."""
    if kind == "fourier":
        if order is None:
            raise ValueError("a Fourier-harmonic model needs its circumferential order")
        return Fourier(order)
    return kind


def strain_voigt(u, kind):
    """Engineering strain 6-vector of displacement ``u`` [m] (dimensionless)."""
    g = ufl.grad(u)
    if kind == "3d":
        return ufl.as_vector(
            [g[0, 0], g[1, 1], g[2, 2], g[1, 2] + g[2, 1], g[0, 2] + g[2, 0], g[0, 1] + g[1, 0]]
        )
    if isinstance(kind, Fourier):
        n = kind.order
        r = ufl.SpatialCoordinate(extract_unique_domain(u))[0]
        ur, ut, uz = u[0], u[1], u[2]
        return ufl.as_vector([g[0, 0], (ur + n * ut) / r, g[2, 1], g[1, 1] - n * uz / r,
                              g[0, 1] + g[2, 0], g[1, 0] - (ut + n * ur) / r])
    if kind == "axisymmetric":
        r = ufl.SpatialCoordinate(extract_unique_domain(u))[0]
        return ufl.as_vector([g[0, 0], u[0] / r, g[1, 1], 0, g[0, 1] + g[1, 0], 0])
    if kind == "plane_strain":
        return ufl.as_vector([g[0, 0], 0, g[1, 1], 0, g[0, 1] + g[1, 0], 0])
    raise ValueError(f"unknown model kind {kind!r}")


def electric_field(phi, kind):
    """E = -grad(phi) as a 3D vector [V/m] for electric potential ``phi`` [V]."""
    g = ufl.grad(phi)
    if kind == "3d":
        return -g
    if isinstance(kind, Fourier):
        r = ufl.SpatialCoordinate(extract_unique_domain(phi))[0]
        return ufl.as_vector([-g[0], kind.order * phi / r, -g[1]])
    if kind in ("axisymmetric", "plane_strain"):
        return ufl.as_vector([-g[0], 0, -g[1]])
    raise ValueError(f"unknown model kind {kind!r}")


def displacement_3d(u, kind):
    """Displacement as a 3D vector in the model's 3D axes (hoop/out-of-plane component 0; the
    amplitudes (U_r, U_theta, U_z) of a Fourier model)."""
    if kind == "3d" or isinstance(kind, Fourier):
        return u
    return ufl.as_vector([u[0], 0, u[1]])


def displacement_components(kind) -> int:
    """Number of displacement unknowns per node."""
    return 3 if kind == "3d" or isinstance(kind, Fourier) else 2


def volume_weight(mesh, kind, thickness_m: float = 1.0):
    """Factor turning the mesh measure into physical volume [m^3 per mesh unit]: 2*pi*r for
    axisymmetric (integrals are over the whole body of revolution), pi*r for a Fourier model of
    order n >= 1 (the integral of cos^2 n theta or sin^2 n theta over a turn; 2*pi*r for n = 0), the
    out-of-plane thickness for plane strain, 1 in 3D."""
    if kind == "axisymmetric":
        return 2 * math.pi * ufl.SpatialCoordinate(mesh)[0]
    if isinstance(kind, Fourier):
        return (2 * math.pi if kind.order == 0 else math.pi) * ufl.SpatialCoordinate(mesh)[0]
    if kind == "plane_strain":
        return thickness_m
    if kind == "fourier":
        raise ValueError("a Fourier-harmonic model needs its circumferential order (forms.kinematics.kinematics)")
    return 1.0
