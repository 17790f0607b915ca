"""Axisymmetric Langevin transducer of the percussion drill (mesh coordinates r, z).

From the tip (z = 0) upward: a tip section of radius ``tip_radius_m``, a conical transition to the
front-mass radius, the front mass, a stack of PZT rings with electrodes at every interface, and the
back mass. An optional steel bolt (r < ``bolt_radius_m``) runs from the front mass through the
stack into the back mass, separated from the rings by an air gap.

Cell names: ``horn`` (tip, cone and front mass), ``back``, ``bolt``, ``piezo_0`` ... ``piezo_{n-1}``
(ring 0 next to the front mass; even rings poled +z, odd rings -z so that all rings strain in
phase). Facet names: ``tip`` (z = 0 face), ``back_face``, ``electrode_hot`` (odd interfaces),
``electrode_ground`` (even interfaces, including the two steel-ceramic faces), ``outer``.
"""

from __future__ import annotations

from dataclasses import dataclass

import gmsh
from mpi4py import MPI

from app.case.validate import param
from geometry.meshdata import GmshSession, MeshData, from_gmsh_model


@dataclass(frozen=True)
class TransducerParameters:
    tip_radius_m: float = param(0.006, gt=0)
    tip_length_m: float = param(0.040, gt=0)
    cone_length_m: float = param(0.010, ge=0)
    front_radius_m: float = param(0.0125, gt=0)
    front_length_m: float = param(0.015, gt=0)
    ring_count: int = param(4, ge=2)
    ring_thickness_m: float = param(0.005, gt=0)
    ring_inner_radius_m: float = param(0.005, ge=0)
    back_radius_m: float = param(0.0125, gt=0)
    back_length_m: float = param(0.030, gt=0)
    bolt: bool = param(True)
    bolt_radius_m: float = param(0.004, gt=0)
    bolt_depth_in_masses_m: float = param(0.010, gt=0, doc="bolt length inside front and back mass")
    mesh_size_m: float = param(0.0015, gt=0)
    ceramic_mesh_size_m: float = param(0.001, gt=0)

    def check(self, file, prefix):
        from app.errors import CaseError

        if self.ring_count % 2:
            raise CaseError(file, f"{prefix}.ring_count", "must be even so both stack ends are grounded")
        if self.ring_inner_radius_m >= self.front_radius_m:
            raise CaseError(file, f"{prefix}.ring_inner_radius_m", "must be smaller than front_radius_m")
        if self.bolt and self.bolt_radius_m >= self.ring_inner_radius_m:
            raise CaseError(file, f"{prefix}.bolt_radius_m", "must be smaller than ring_inner_radius_m")
        if self.bolt and self.bolt_depth_in_masses_m >= min(self.front_length_m, self.back_length_m):
            raise CaseError(file, f"{prefix}.bolt_depth_in_masses_m", "must be shorter than the masses")

    @property
    def stack_bottom_m(self) -> float:
        return self.tip_length_m + self.cone_length_m + self.front_length_m

    @property
    def length_m(self) -> float:
        return self.stack_bottom_m + self.ring_count * self.ring_thickness_m + self.back_length_m


def build_transducer(comm: MPI.Comm, p: TransducerParameters, kind: str = "axisymmetric") -> MeshData:
    if kind != "axisymmetric":
        raise ValueError(f"transducer builder supports axisymmetric, not {kind}")
    with GmshSession(comm, "transducer"):
        if comm.rank == 0:
            _build(p)
        return from_gmsh_model(comm, 2)


def _build(p: TransducerParameters) -> None:
    occ = gmsh.model.occ
    z_cone = p.tip_length_m
    z_front = z_cone + p.cone_length_m
    z_stack = p.stack_bottom_m
    z_back = z_stack + p.ring_count * p.ring_thickness_m
    z_top = p.length_m
    hole = p.ring_inner_radius_m if p.bolt else 0.0

    parts: dict[str, list[int]] = {"horn": [], "back": [], "bolt": []}
    parts["horn"].append(occ.addRectangle(0, 0, 0, p.tip_radius_m, z_cone))
    if p.cone_length_m > 0:
        pts = [occ.addPoint(0, z_cone, 0), occ.addPoint(p.tip_radius_m, z_cone, 0),
               occ.addPoint(p.front_radius_m, z_front, 0), occ.addPoint(0, z_front, 0)]
        lines = [occ.addLine(pts[i], pts[(i + 1) % 4]) for i in range(4)]
        parts["horn"].append(occ.addPlaneSurface([occ.addCurveLoop(lines)]))
    parts["horn"].append(occ.addRectangle(0, z_front, 0, p.front_radius_m, z_stack - z_front))
    parts["back"].append(occ.addRectangle(0, z_back, 0, p.back_radius_m, z_top - z_back))
    rings = []
    for k in range(p.ring_count):
        z0 = z_stack + k * p.ring_thickness_m
        r_in = p.ring_inner_radius_m
        rings.append(occ.addRectangle(r_in, z0, 0, p.front_radius_m - r_in, p.ring_thickness_m)
                     if r_in > 0 else occ.addRectangle(0, z0, 0, p.front_radius_m, p.ring_thickness_m))
    if p.bolt:
        z0 = z_stack - p.bolt_depth_in_masses_m
        parts["bolt"].append(occ.addRectangle(0, z0, 0, p.bolt_radius_m,
                                              z_back + p.bolt_depth_in_masses_m - z0))
    all_parts = [(2, s) for group in parts.values() for s in group] + [(2, s) for s in rings]
    occ.fragment(all_parts, [])
    occ.synchronize()

    def classify(surface: int) -> str:
        r_c, z_c, _ = occ.getCenterOfMass(2, surface)
        if z_stack < z_c < z_back:
            if p.bolt and r_c < p.bolt_radius_m:
                return "bolt"
            k = int((z_c - z_stack) // p.ring_thickness_m)
            return f"piezo_{k}"
        if p.bolt and r_c < p.bolt_radius_m and (z_stack - p.bolt_depth_in_masses_m < z_c < z_back
                                                  + p.bolt_depth_in_masses_m):
            return "bolt"
        return "horn" if z_c < z_stack else "back"

    groups: dict[str, list[int]] = {}
    for _, surface in gmsh.model.getEntities(2):
        groups.setdefault(classify(surface), []).append(surface)
    names = ["horn", "back", "bolt"] + [f"piezo_{k}" for k in range(p.ring_count)]
    for tag, name in enumerate(names, start=1):
        if groups.get(name):
            gmsh.model.addPhysicalGroup(2, groups[name], tag)
            gmsh.model.setPhysicalName(2, tag, name)

    eps = 1e-3 * min(p.ring_thickness_m, p.tip_radius_m)  # OCC boxes carry a tolerance margin
    r_lo = max(hole, 0.0)

    def lines_in(r0, z0, r1, z1):
        return [c for _, c in gmsh.model.getEntitiesInBoundingBox(r0 - eps, z0 - eps, -eps, r1 + eps,
                                                                   z1 + eps, eps, dim=1)]

    facets = {
        "tip": lines_in(0, 0, p.tip_radius_m, 0),
        "back_face": lines_in(0, z_top, p.back_radius_m, z_top),
        "electrode_hot": [],
        "electrode_ground": [],
    }
    for k in range(p.ring_count + 1):
        z_k = z_stack + k * p.ring_thickness_m
        key = "electrode_hot" if k % 2 else "electrode_ground"
        facets[key] += [c for c in lines_in(r_lo, z_k, p.front_radius_m, z_k)
                        if _is_horizontal(c, eps)]
    boundary = {c for _, c in gmsh.model.getBoundary(gmsh.model.getEntities(2), combined=True,
                                                     oriented=False)}
    named = set(facets["tip"]) | set(facets["back_face"])
    facets["outer"] = sorted(c for c in boundary if c not in named and not _on_axis(c))
    for tag, (name, ids) in enumerate(facets.items(), start=1):
        gmsh.model.addPhysicalGroup(1, ids, tag)
        gmsh.model.setPhysicalName(1, tag, name)

    gmsh.option.setNumber("Mesh.MeshSizeMax", p.mesh_size_m)
    field = gmsh.model.mesh.field
    box = field.add("Box")
    for key, value in (("XMin", -1.0), ("XMax", 1.0), ("YMin", z_stack - eps), ("YMax", z_back + eps),
                       ("ZMin", -1.0), ("ZMax", 1.0), ("VIn", p.ceramic_mesh_size_m),
                       ("VOut", p.mesh_size_m)):
        field.setNumber(box, key, value)
    field.setAsBackgroundMesh(box)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.model.mesh.generate(2)


def _is_horizontal(curve: int, tolerance_m: float) -> bool:
    _, z0, _, _, z1, _ = gmsh.model.getBoundingBox(1, curve)
    return abs(z1 - z0) < tolerance_m


def _on_axis(curve: int) -> bool:
    r0, _, _, r1, _, _ = gmsh.model.getBoundingBox(1, curve)
    return r1 < 1e-6
