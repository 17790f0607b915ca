"""Validation specimens: PZT bars (IEEE Std 176 length-extensional 33 bar) and discs.

Axisymmetric models use mesh coordinates (r, z); 3D models (x, y, z). Electrodes are the faces
normal to z. Facet names: ``bottom`` (z = 0), ``top`` (z = length), ``side``; axisymmetric
models also name ``axis`` (r = 0). Cell name: ``piezo``.
"""

from __future__ import annotations

from dataclasses import dataclass

import gmsh
from mpi4py import MPI

from app.case.validate import param
from geometry.meshdata import GmshSession, MeshData, from_gmsh_model


@dataclass(frozen=True)
class BarParameters:
    """Length-extensional bar: square w x w section in 3D, or a round rod of radius w/2."""

    length_m: float = param(0.02, gt=0)
    width_m: float = param(0.002, gt=0, doc="square side (3D) or diameter (axisymmetric)")
    axial_divisions: int = param(20, ge=1)
    lateral_divisions: int = param(2, ge=1)


@dataclass(frozen=True)
class DiscParameters:
    """Thickness-poled disc (axisymmetric)."""

    radius_m: float = param(0.01, gt=0)
    thickness_m: float = param(0.001, gt=0)
    radial_divisions: int = param(40, ge=1)
    thickness_divisions: int = param(4, ge=1)


def _structured_rectangle(width: float, height: float, nx: int, ny: int, axisymmetric: bool):
    """Transfinite rectangle [0, width] x [0, height] with named boundary lines."""
    occ = gmsh.model.occ
    surface = occ.addRectangle(0, 0, 0, width, height)
    occ.synchronize()
    lines = {}
    for _, line in gmsh.model.getBoundary([(2, surface)], oriented=False):
        x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, line)
        # A horizontal line's box is flatter than it is wide (OCC boxes carry an absolute tolerance
        # margin, so a threshold tied to one dimension misclassifies thin specimens)
        if abs(y1 - y0) < abs(x1 - x0):
            lines["bottom" if y0 < 0.5 * height else "top"] = line
            gmsh.model.mesh.setTransfiniteCurve(line, nx + 1)
        else:
            name = "axis" if (x0 < 0.5 * width and axisymmetric) else ("side" if x0 > 0.5 * width else "left")
            lines[name] = line
            gmsh.model.mesh.setTransfiniteCurve(line, ny + 1)
    gmsh.model.mesh.setTransfiniteSurface(surface)
    gmsh.model.addPhysicalGroup(2, [surface], 1)
    gmsh.model.setPhysicalName(2, 1, "piezo")
    for tag, name in enumerate(("bottom", "top", "side", "axis", "left"), start=1):
        if name in lines:
            gmsh.model.addPhysicalGroup(1, [lines[name]], tag)
            gmsh.model.setPhysicalName(1, tag, name)
    gmsh.model.mesh.generate(2)


def build_bar(comm: MPI.Comm, params: BarParameters, kind: str) -> MeshData:
    """Bar along z from 0 to ``length_m``: a rod (axisymmetric), a square prism (3D) or a strip of
    width ``width_m`` (plane strain, mesh coordinates (x, z))."""
    if kind not in ("axisymmetric", "plane_strain", "3d"):
        raise ValueError(f"bar builder does not support {kind}")
    with GmshSession(comm, "bar"):
        if comm.rank == 0:
            if kind == "axisymmetric":
                _structured_rectangle(0.5 * params.width_m, params.length_m, params.lateral_divisions,
                                      params.axial_divisions, axisymmetric=True)
            elif kind == "plane_strain":
                _structured_rectangle(params.width_m, params.length_m, params.lateral_divisions,
                                      params.axial_divisions, axisymmetric=False)
            elif kind == "3d":
                _structured_box(params)
        return from_gmsh_model(comm, 3 if kind == "3d" else 2)


def _structured_box(params: BarParameters):
    occ = gmsh.model.occ
    w, L = params.width_m, params.length_m
    volume = occ.addBox(-w / 2, -w / 2, 0, w, w, L)
    occ.synchronize()
    for _, curve in gmsh.model.getEntities(1):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(1, curve)
        n = params.axial_divisions if (z1 - z0) > 0.5 * L else params.lateral_divisions
        gmsh.model.mesh.setTransfiniteCurve(curve, n + 1)
    faces = {"bottom": [], "top": [], "side": []}
    for _, face in gmsh.model.getBoundary([(3, volume)], oriented=False):
        gmsh.model.mesh.setTransfiniteSurface(face)
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, face)
        if z1 - z0 < min(x1 - x0, y1 - y0):       # flatter in z than across: an end face (any aspect)
            faces["bottom" if z0 < 0.5 * L else "top"].append(face)
        else:
            faces["side"].append(face)
    gmsh.model.mesh.setTransfiniteVolume(volume)
    gmsh.model.addPhysicalGroup(3, [volume], 1)
    gmsh.model.setPhysicalName(3, 1, "piezo")
    for tag, (name, ids) in enumerate(faces.items(), start=1):
        gmsh.model.addPhysicalGroup(2, ids, tag)
        gmsh.model.setPhysicalName(2, tag, name)
    gmsh.model.mesh.generate(3)


def build_disc(comm: MPI.Comm, params: DiscParameters, kind: str) -> MeshData:
    """Thickness-poled disc: axisymmetric rectangle [0, R] x [0, t]."""
    if kind != "axisymmetric":
        raise ValueError(f"disc builder supports axisymmetric, not {kind}")
    with GmshSession(comm, "disc"):
        if comm.rank == 0:
            _structured_rectangle(params.radius_m, params.thickness_m, params.radial_divisions,
                                  params.thickness_divisions, axisymmetric=True)
        return from_gmsh_model(comm, 2)


@dataclass(frozen=True)
class RingParameters:
    """Radially poled ring (tube segment) about the z axis, electrodes on the inner and outer faces."""

    mean_radius_m: float = param(0.01, gt=0)
    wall_thickness_m: float = param(0.0005, gt=0)
    height_m: float = param(0.001, gt=0)
    mesh_size_m: float = param(0.0005, gt=0)

    def check(self, file, prefix):
        from app.errors import CaseError

        if self.wall_thickness_m >= 2 * self.mean_radius_m:
            raise CaseError(file, f"{prefix}.wall_thickness_m", "must be smaller than the mean diameter")


def build_ring(comm: MPI.Comm, params: RingParameters, kind: str) -> MeshData:
    """Ring: rectangle [r_i, r_o] x [0, h] in (r, z) (axisymmetric, fourier), or the 3D solid of revolution."""
    r_i = params.mean_radius_m - 0.5 * params.wall_thickness_m
    r_o = params.mean_radius_m + 0.5 * params.wall_thickness_m
    h = params.height_m
    with GmshSession(comm, "ring"):
        if comm.rank == 0:
            occ = gmsh.model.occ
            if kind in ("axisymmetric", "fourier"):
                entity = (2, occ.addRectangle(r_i, 0, 0, params.wall_thickness_m, h))
            elif kind == "3d":
                outer = occ.addCylinder(0, 0, 0, 0, 0, h, r_o)
                inner = occ.addCylinder(0, 0, 0, 0, 0, h, r_i)
                entity = occ.cut([(3, outer)], [(3, inner)])[0][0]
            else:
                raise ValueError(f"ring builder supports axisymmetric, fourier and 3d, not {kind}")
            occ.synchronize()
            dim = entity[0]
            faces = {"inner": [], "outer": [], "bottom": [], "top": []}
            for _, b in gmsh.model.getBoundary([entity], oriented=False):
                x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(dim - 1, b)
                if dim == 2:
                    if abs(x1 - x0) < 1e-3 * params.wall_thickness_m:
                        faces["inner" if x0 < params.mean_radius_m else "outer"].append(b)
                    else:
                        faces["bottom" if y0 < 0.5 * h else "top"].append(b)
                else:
                    if abs(z1 - z0) < 1e-3 * h:
                        faces["bottom" if z0 < 0.5 * h else "top"].append(b)
                    else:
                        faces["inner" if x1 < params.mean_radius_m else "outer"].append(b)
            gmsh.model.addPhysicalGroup(dim, [entity[1]], 1)
            gmsh.model.setPhysicalName(dim, 1, "piezo")
            for tag, (name, ids) in enumerate(faces.items(), start=1):
                gmsh.model.addPhysicalGroup(dim - 1, ids, tag)
                gmsh.model.setPhysicalName(dim - 1, tag, name)
            gmsh.option.setNumber("Mesh.MeshSizeMax", params.mesh_size_m)
            gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * params.mesh_size_m)
            gmsh.model.mesh.generate(dim)
        return from_gmsh_model(comm, 3 if kind == "3d" else 2)
