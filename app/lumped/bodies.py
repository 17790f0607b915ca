"""The lumped drill's bodies drawn with shapes for ParaView and meshio (``[lumped.output] bodies_interval_s``):
the file ``transient_bodies.xdmf`` the FE and modal tiers write beside their fields (app/transient/body_shapes.py,
app/transient/fields.py BodySeriesExport), here alone, the lumped tier having no mesh.

The lumped model holds each part as one vertical coordinate, zero where the parts rest on each other unloaded
(app/lumped/outputs.py), so the drawing stacks them touching at zero, in 3D with z up, the rock surface at z = 0:

- ``rock``: a slab below z = 0 moving with the rock surface (``rock_surface_displacement_m`` = -d3), as wide as half
  the scene and half as deep (the FE tiers' rule for the rock);
- ``stem``: a rod standing on it, of the stem-rock contact's radius (``contact_stem_rock.radius_m``, the flat
  punch), its length from its mass at the ball's density (steel: 40 g, 3 mm -> 180 mm), moving with v;
- ``ball``: the free mass, a sphere of ``free_mass.diameter_m`` on the stem's top face, moving with w;
- ``transducer``: its tip face on the ball, drawn as a cylinder of the ball's diameter in radius and half the stem
  long, moving with the tip displacement x + z (``tip_displacement_m``: the vibration and the rigid motion).

The lumped data give the ball's size and the contact radii; the stem's length and the transducer's size are
drawing choices (the contact laws do not use them), so the picture shows the motion, not the drill's shape.
"""

from __future__ import annotations

import math

import numpy as np

from app.lumped.model import ID3, IV, IW, IX, IZ

#: the drawn bodies in their coordinate order (one vertical coordinate each, packed as (0, 0, value))
NAMES = ("transducer", "ball", "stem", "rock")
_SLICES = {name: slice(3 * k, 3 * k + 3) for k, name in enumerate(NAMES)}


def _sizes(section) -> tuple[float, float, float, float]:
    """(ball radius, stem radius, stem length, transducer tip length) [m] of the drawing."""
    ball_radius = section.free_mass.diameter_m / 2
    stem_radius = section.contact_stem_rock.radius_m
    stem_length = section.stem.mass_kg / (section.free_mass.density_kg_per_m3 * math.pi * stem_radius**2)
    return ball_radius, stem_radius, stem_length, stem_length / 2


def rest_heights(section) -> np.ndarray:
    """The bodies' reference points' heights [m] at rest (all coordinates zero), in the order of NAMES: the
    transducer's tip face, the ball's centre, the stem's top face, the rock's surface."""
    ball_radius, _, stem_length, _ = _sizes(section)
    return np.array([stem_length + 2 * ball_radius, stem_length + ball_radius, stem_length, 0.0])


def body_meshes(section):
    """The :class:`app.transient.body_shapes.BodyMeshes` of the lumped drill (``section``: the [lumped] section)."""
    from app.transient.body_shapes import BodyMeshes, cylinder_shape, sphere_shape

    ball_radius, stem_radius, stem_length, tip_length = _sizes(section)
    patch = (stem_length + 2 * ball_radius + tip_length) / 2
    shapes = {"transducer": cylinder_shape(2 * ball_radius, 0.0, tip_length), "ball": sphere_shape(ball_radius),
              "stem": cylinder_shape(stem_radius, -stem_length, 0.0),
              "rock": cylinder_shape(patch, -patch / 2, 0.0, kind="slab")}
    bodies = [(name, [0.0, 0.0, height], [], [shapes[name]]) for name, height in zip(NAMES, rest_heights(section))]
    return BodyMeshes.from_shapes(bodies, 3, "3d", _SLICES)


def body_coordinates(section, y: np.ndarray) -> np.ndarray:
    """The packed coordinates (each body's reference point, x y z [m]) of :func:`body_meshes`' bodies at the lumped
    state ``y``: the rest heights raised by the tip displacement x + z, w, v and the rock surface -d3."""
    z = np.zeros(3 * len(NAMES))
    z[2::3] = rest_heights(section) + np.array([y[IX] + y[IZ], y[IW], y[IV], -y[ID3]])
    return z
