"""Wedge-wave motor stator and its thin-ring test piece: bodies of revolution about z, built by
revolving an (r, z) profile in angular pieces whose edges are the electrode-strip edges.

Stator (from z = 0 up): a stainless-steel base (annulus, bottom clamped), the radially poled PZT
tube, and the steel wedge ring (a collar plus the wedge). The wedge's outer face is the cylinder
r = tube_outer_radius_m (flush with the tube); its inner face leans ``wedge_angle_deg`` off the
axis, so the wedge narrows upward to a flat tip of width ``tip_width_m`` at the tip radius.

Cell names: ``base``, ``tube``, ``wedge``. Facet names: ``inner`` (tube inner wall, the common
electrode), ``A1``..``A4`` and ``B1``..``B4`` (outer comb strips; A centred at 0, 90, 180, 270 deg,
B shifted by ``phase_shift_deg``), ``sensor`` (one outer strip between B1 and A2), ``contact``
(a band of height ``contact_band_m`` on the inclined face, centred ``contact_depth_m`` below the
tip), ``tip`` (the flat tip), ``bottom`` (base bottom). The outer strips stop
``electrode_margin_m`` short of the tube ends, where the tube touches the (grounded) steel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import gmsh
import numpy as np
from mpi4py import MPI

from app.case.validate import param
from geometry.meshdata import GmshSession, MeshData, from_gmsh_model

PHASE_CENTRES_DEG = (0.0, 90.0, 180.0, 270.0)


@dataclass(frozen=True)
class StatorParameters:
    """Dimensions of the wedge-wave stator (defaults: the calibrated design of docs/motor-stator.md)."""

    base_height_m: float = param(0.003, gt=0)
    base_inner_radius_m: float | None = param(None, gt=0, doc="default: tube_inner_radius_m")
    base_outer_radius_m: float | None = param(None, gt=0, doc="default: tube_outer_radius_m")
    tube_inner_radius_m: float = param(0.0115, gt=0)
    tube_outer_radius_m: float = param(0.0135, gt=0, doc="also the wedge's outer face and tip radius")
    tube_height_m: float = param(0.008, gt=0)
    collar_height_m: float = param(0.001, gt=0, doc="full-width steel ring between tube and wedge")
    wedge_height_m: float = param(0.005, gt=0, doc="the tuning knob of F(1,4)")
    wedge_angle_deg: float = param(15.0, gt=0, lt=45, doc="inner face off the axis")
    tip_width_m: float = param(0.0003, gt=0)
    contact_depth_m: float = param(0.00126, gt=0, doc="contact circle below the tip, along z")
    contact_band_m: float = param(0.0003, gt=0, doc="height of the contact facet band")
    strip_width_deg: float = param(18.0, gt=0, lt=22.5, doc="angular width of each A/B strip")
    phase_shift_deg: float = param(22.5, doc="B strips' offset from A (a quarter wavelength for n = 4)")
    sensor_centre_deg: float = param(56.25)
    sensor_width_deg: float = param(9.0, gt=0)
    sensor2_centre_deg: float | None = param(
        None, doc="a second sensor strip 'sensor2' of the same width (22.5 deg from the first: the two read the "
                  "n = 4 wave in quadrature, and as floating electrodes they stiffen both modes of the pair alike)")
    guard_width_deg: float | None = param(
        None, gt=0, lt=22.5, doc="guard strips (facet group 'guard', for grounding) of this width centred on the "
                                 "22.5 deg pitch where no A/B strip or the sensor is; default: none (bare wall)")
    electrode_margin_m: float = param(0.0005, ge=0, doc="axial gap between outer strips and tube ends")
    mesh_size_m: float = param(0.0012, gt=0, doc="element size away from the tip")
    tip_mesh_size_m: float = param(0.0005, gt=0, doc="element size at the wedge tip (swept, fourier: also at the "
                                                     "wedge root and the outer electrodes' ends)")
    mesh_method: Literal["free", "swept"] = param(
        "free", doc="3d: 'free' gmsh tetrahedra in the revolved solid, or 'swept': the (r, z) profile's triangles "
                    "(the fourier model's mesh) revolved in layers, each prism cut into three tetrahedra "
                    "(docs/motor-stator.md, meshes). The keys marked (swept) need 'swept' (a fourier model is "
                    "always the swept method's profile)")
    arc_mesh_size_m: float | None = param(
        None, gt=0, doc="(swept) layer length round the circumference at the tube's outer radius; default: "
                        "mesh_size_m. Every electrode edge is a layer boundary")
    mesh_refinement: float = param(
        1.0, gt=0, doc="(swept) divides every mesh size (mesh, tip, arc): one knob for a mesh study")
    wedge_root_fillet_m: float = param(
        0.0, ge=0, doc="(swept) radius of a fillet where the wedge's inner face meets the collar (0: a sharp "
                       "re-entrant corner)")
    tube_layers: int = param(
        1, ge=1, le=15, doc="(swept) odd number of PZT layers through the wall, with internal electrodes "
                            "between them: a multilayer wall, the field per volt times the layer count. "
                            "Electrodes from the inner wall out: ground, drive (segmented like the outer "
                            "wall), ground, ..., drive (the outer wall); the drive electrodes take the outer "
                            "segments' names, the internal ground ones 'inner'. Cell groups: 'tube' (layers "
                            "with ground inside, to be poled 'radial') and 'tube_reversed' (drive inside, "
                            "'-radial')")
    negative_phase_segments: bool = param(
        False, doc="(swept) the segments 45 deg after each A and B strip (half a wavelength of n = 4) are named "
                   "'Am1'..'Am4' and 'Bm1'..'Bm4' instead of guards: driven in antiphase they double the n = 4 "
                   "drive and cancel n = 0 and n = 8 (the all-segment drive)")
    sensor_height_m: float | None = param(
        None, gt=0, doc="(swept) sensors as patches of this height at the top of the outer wall (above the "
                        "segment at their angle, separated by sensor_gap_m) instead of full-height segments")
    sensor_gap_m: float = param(0.0003, gt=0, doc="(swept) bare axial gap between a sensor patch and the segment "
                                                  "below it")
    profile_cells: Literal["triangles", "quadrilaterals"] = param(
        "triangles", doc="(swept) the (r, z) profile's cells: triangles (a swept mesh of prisms cut into tetrahedra) "
                         "or quadrilaterals (hexahedra; straight-sided only)")
    alternate_layers: bool = param(
        False, doc="(swept) cut the prisms of every second layer of a piece the other way round")
    geometry_degree: int = param(
        1, ge=1, le=2, doc="(swept, triangles) 1: straight-sided tetrahedra (the circles become polygons of chords); "
                           "2: quadratic (curved) ones, the revolution of the profile mesh up to the quadratic "
                           "interpolation of its circles (docs/motor-stator.md: worth ~4 Hz on F(1,4))")
    sector_deg: float | None = param(
        None, gt=0, le=180, doc="(swept) mesh only the sector of this angle from strip A1's lower edge, a multiple of "
                                "the 22.5 deg electrode pitch: the whole mesh's layers over that angle, one period of "
                                "a cyclically symmetric model (modal.cyclic)")
    full_outer_electrode: bool = param(
        False, doc="(swept) one electrode 'outer' over the whole outer wall and every internal drive radius, slits "
                   "included, as a fourier model has (the mesh is the segmented one's): the reference that isolates "
                   "the segments' effect")

    def radii(self):
        r_i, r_o = self.tube_inner_radius_m, self.tube_outer_radius_m
        return (self.base_inner_radius_m or r_i, self.base_outer_radius_m or r_o, r_i, r_o)

    @property
    def wedge_base_width_m(self) -> float:
        return self.tip_width_m + self.wedge_height_m * math.tan(math.radians(self.wedge_angle_deg))

    @property
    def tip_z_m(self) -> float:
        return self.base_height_m + self.tube_height_m + self.collar_height_m + self.wedge_height_m

    def contact_point(self) -> tuple[float, float]:
        """(r, z) of the contact circle on the inclined face [m]."""
        z = self.tip_z_m - self.contact_depth_m
        r = self.tube_outer_radius_m - self.tip_width_m - self.contact_depth_m * math.tan(
            math.radians(self.wedge_angle_deg))
        return r, z

    def check(self, file, prefix):
        from app.errors import CaseError

        b_i, b_o, r_i, r_o = self.radii()
        if r_i >= r_o:
            raise CaseError(file, f"{prefix}.tube_inner_radius_m", "must be smaller than tube_outer_radius_m")
        if b_i >= b_o:
            raise CaseError(file, f"{prefix}.base_inner_radius_m", "must be smaller than base_outer_radius_m")
        if self.wedge_base_width_m >= r_o:
            raise CaseError(file, f"{prefix}.wedge_height_m", "the wedge is wider than the tip radius")
        if self.contact_depth_m + 0.5 * self.contact_band_m >= self.wedge_height_m:
            raise CaseError(file, f"{prefix}.contact_depth_m", "the contact band must lie on the inclined face")
        if 2 * self.electrode_margin_m >= self.tube_height_m:
            raise CaseError(file, f"{prefix}.electrode_margin_m", "leaves no room for the outer strips")
        if self.mesh_method == "free":
            for key, unset in (("arc_mesh_size_m", self.arc_mesh_size_m is None),
                               ("mesh_refinement", self.mesh_refinement == 1.0),
                               ("wedge_root_fillet_m", self.wedge_root_fillet_m == 0.0),
                               ("tube_layers", self.tube_layers == 1),
                               ("negative_phase_segments", not self.negative_phase_segments),
                               ("sensor_height_m", self.sensor_height_m is None),
                               ("full_outer_electrode", not self.full_outer_electrode),
                               ("sector_deg", self.sector_deg is None),
                               ("geometry_degree", self.geometry_degree == 1),
                               ("profile_cells", self.profile_cells == "triangles")):
                if not unset:
                    raise CaseError(file, f"{prefix}.{key}", "needs mesh_method = 'swept'")
        if self.sector_deg is not None and abs(self.sector_deg / 22.5 - round(self.sector_deg / 22.5)) > 1e-9:
            raise CaseError(file, f"{prefix}.sector_deg", "must be a multiple of the 22.5 deg electrode pitch")
        if self.tube_layers % 2 == 0:
            raise CaseError(file, f"{prefix}.tube_layers", "must be odd (the outer wall carries the drive segments)")
        if self.sensor_height_m is not None and (
                self.sensor_height_m + self.sensor_gap_m >= self.tube_height_m - 2 * self.electrode_margin_m):
            raise CaseError(file, f"{prefix}.sensor_height_m", "sensor patch and gap leave no room for the segment")
        if self.wedge_root_fillet_m > 0 and self.wedge_root_fillet_m >= 0.5 * self.wedge_height_m:
            raise CaseError(file, f"{prefix}.wedge_root_fillet_m", "must be well below the wedge height")
        self._check_strips_apart(file, prefix)

    def _check_strips_apart(self, file, prefix) -> None:
        """Each outer strip is its own facet group: two strips on the same wall area would leave one group
        empty (a facet carries one tag). The key named is the one that places the later strip."""
        from app.errors import CaseError

        strips = list(self.strips().items())
        for i, (name, arc) in enumerate(strips):
            for other, other_arc in strips[:i]:
                if _arcs_overlap(arc, other_arc):
                    key = ("sensor2_centre_deg" if name == "sensor2" else "sensor_centre_deg" if name == "sensor"
                           else "phase_shift_deg")
                    raise CaseError(file, f"{prefix}.{key}",
                                    f"the {name!r} strip ({arc[0]:g} to {arc[1]:g} deg) overlaps the {other!r} strip "
                                    f"({other_arc[0]:g} to {other_arc[1]:g} deg): move it or narrow the strips")

    def strips(self) -> dict[str, tuple[float, float]]:
        """Angular extent [deg] of each outer strip, in [0, 360)."""
        half = 0.5 * self.strip_width_deg
        out = {}
        for k, centre in enumerate(PHASE_CENTRES_DEG, start=1):
            out[f"A{k}"] = (centre - half, centre + half)
            out[f"B{k}"] = (centre + self.phase_shift_deg - half, centre + self.phase_shift_deg + half)
        out["sensor"] = (self.sensor_centre_deg - 0.5 * self.sensor_width_deg,
                         self.sensor_centre_deg + 0.5 * self.sensor_width_deg)
        if self.sensor2_centre_deg is not None:
            out["sensor2"] = (self.sensor2_centre_deg - 0.5 * self.sensor_width_deg,
                              self.sensor2_centre_deg + 0.5 * self.sensor_width_deg)
        return out

    def guards(self) -> list[tuple[float, float]]:
        """Angular extents [deg] of the guard strips: on the 22.5 deg pitch of the A/B strips, the
        places no strip covers (the sensor's included)."""
        if self.guard_width_deg is None:
            return []
        half = 0.5 * self.guard_width_deg
        taken = list(self.strips().values())
        out = []
        for k in range(16):
            arc = (22.5 * k - half, 22.5 * k + half)
            if not any(_arcs_overlap(arc, other) for other in taken):
                out.append(arc)
        return out

    # -- the swept and fourier meshes' layout ---------------------------------------------------------
    def sizes(self) -> tuple[float, float, float]:
        """(profile, tip, arc) element sizes [m] after ``mesh_refinement``."""
        arc = self.arc_mesh_size_m or self.mesh_size_m
        return (self.mesh_size_m / self.mesh_refinement, self.tip_mesh_size_m / self.mesh_refinement,
                arc / self.mesh_refinement)

    def tube_radii(self) -> list[float]:
        """Radii [m] of the electrodes through the wall, inner wall first: ground, drive, ..., drive."""
        _, _, r_i, r_o = self.radii()
        return [r_i + (r_o - r_i) * k / self.tube_layers for k in range(self.tube_layers + 1)]

    def segments(self) -> dict[str, tuple[float, float]]:
        """Angular extent [deg] of every full-height segment of a drive electrode (outer wall and internal
        drive radii), named: A1..A4, B1..B4; the sensors unless they are patches; with
        negative_phase_segments Am1..Am4 and Bm1..Bm4 45 deg after A and B (where no sensor is); the
        guards (one name, 'guard') on the rest of the 22.5 deg pitch."""
        half = 0.5 * self.strip_width_deg
        out = {name: arc for name, arc in self.strips().items()
               if self.sensor_height_m is None or not name.startswith("sensor")}
        if self.negative_phase_segments:
            for k, centre in enumerate(PHASE_CENTRES_DEG, start=1):
                for name, c in ((f"Am{k}", centre + 45.0), (f"Bm{k}", centre + 45.0 + self.phase_shift_deg)):
                    arc = (c - half, c + half)
                    if not any(_arcs_overlap(arc, other) for other in out.values()):
                        out[name] = arc
        if self.guard_width_deg is not None:
            g_half = 0.5 * self.guard_width_deg
            guards = [(22.5 * k - g_half, 22.5 * k + g_half) for k in range(16)]
            guards = [arc for arc in guards if not any(_arcs_overlap(arc, other) for other in out.values())]
            for k, arc in enumerate(guards):
                out[f"guard#{k}"] = arc
        return out

    def sensor_patches(self) -> dict[str, tuple[float, float]]:
        """Angular extent [deg] of the sensor patches (sensor_height_m set), else none."""
        if self.sensor_height_m is None:
            return {}
        return {name: arc for name, arc in self.strips().items() if name.startswith("sensor")}

    def drive_facet_name(self, theta_deg: float, z: float, outer: bool) -> str | None:
        """Facet group of a drive-electrode facet at angle ``theta_deg`` and height ``z`` (on the outer wall
        if ``outer``, else an internal drive radius), or None where the wall is bare."""
        if self.full_outer_electrode:
            return "outer"
        if outer:
            z_top = self.base_height_m + self.tube_height_m - self.electrode_margin_m
            for name, arc in self.sensor_patches().items():
                if _in_arc(theta_deg, arc):
                    if z > z_top - self.sensor_height_m:
                        return name
                    if z > z_top - self.sensor_height_m - self.sensor_gap_m:
                        return None
        for name, arc in self.segments().items():
            if _in_arc(theta_deg, arc):
                if name.startswith("sensor") and not outer:
                    return None       # under a full-height sensor the internal drive electrode is left out
                return name.split("#")[0]
        return None

    def facet_names_3d(self) -> list[str]:
        """Every facet group name a swept mesh may carry."""
        if self.full_outer_electrode:
            return ["inner", "outer", "contact", "tip", "bottom"]
        names = ["inner", *dict.fromkeys(n.split("#")[0] for n in self.segments()), *self.sensor_patches()]
        return list(dict.fromkeys(names)) + ["contact", "tip", "bottom"]


@dataclass(frozen=True)
class ThinRingParameters:
    """Rectangular-section ring about z: radial thickness x axial height, mean radius R."""

    mean_radius_m: float = param(0.02, gt=0)
    radial_thickness_m: float = param(0.0005, gt=0)
    axial_height_m: float = param(0.001, gt=0)
    mesh_size_m: float = param(0.0005, gt=0)
    angular_pieces: int = param(8, ge=3, doc="revolution pieces (same construction as the stator)")

    def check(self, file, prefix):
        from app.errors import CaseError

        if self.radial_thickness_m >= self.mean_radius_m:
            raise CaseError(file, f"{prefix}.radial_thickness_m", "must be smaller than mean_radius_m")


def _polygon(points_rz) -> int:
    """Plane surface in the xz half-plane (x = r, y = 0) from an (r, z) polygon."""
    occ = gmsh.model.occ
    pts = [occ.addPoint(r, 0.0, z) for r, z in points_rz]
    lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
    return occ.addPlaneSurface([occ.addCurveLoop(lines)])


def _revolve(surfaces: list[int], cuts_deg: list[float]) -> list[tuple[int, int]]:
    """Revolve the profile surfaces about z in pieces between consecutive cut angles, glue them."""
    occ = gmsh.model.occ
    cuts = sorted({c % 360.0 for c in cuts_deg})
    if cuts[0] != 0.0:
        cuts = [0.0] + cuts
    cuts.append(360.0)
    volumes = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        copies = occ.copy([(2, s) for s in surfaces])
        if a:
            occ.rotate(copies, 0, 0, 0, 0, 0, 1, math.radians(a))
        out = occ.revolve(copies, 0, 0, 0, 0, 0, 1, math.radians(b - a))
        volumes += [dt for dt in out if dt[0] == 3]
    occ.remove([(2, s) for s in surfaces], recursive=True)
    fragments, _ = occ.fragment(volumes, [])
    occ.removeAllDuplicates()
    occ.synchronize()
    return [dt for dt in gmsh.model.getEntities(3)]


def _face_sample(tag: int):
    """A point on face ``tag`` (its parametric centre) as (r, theta_deg in [0, 360), z)."""
    lo, hi = gmsh.model.getParametrizationBounds(2, tag)
    uv = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])]
    x, y, z = gmsh.model.getValue(2, tag, uv)
    return math.hypot(x, y), math.degrees(math.atan2(y, x)) % 360.0, z


def _in_arc(theta_deg: float, arc: tuple[float, float]) -> bool:
    lo, hi = arc
    return (theta_deg - lo) % 360.0 < (hi - lo)


def _arcs_overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return _in_arc(b[0], a) or _in_arc(a[0], b)


def _add_groups(dim: int, groups: dict[str, list[int]]) -> None:
    for tag, (name, ids) in enumerate(groups.items(), start=1):
        if ids:
            gmsh.model.addPhysicalGroup(dim, ids, tag)
            gmsh.model.setPhysicalName(dim, tag, name)


def _stator_model(p: StatorParameters) -> None:
    b_i, b_o, r_i, r_o = p.radii()
    z_b = p.base_height_m
    z_t = z_b + p.tube_height_m
    z_c = z_t + p.collar_height_m
    z_tip = p.tip_z_m
    tan_w = math.tan(math.radians(p.wedge_angle_deg))
    r_tip_in = r_o - p.tip_width_m
    r_wedge_in = r_o - p.wedge_base_width_m
    r_collar_in = min(r_i, r_wedge_in)
    m = p.electrode_margin_m
    _, z_contact = p.contact_point()
    z_lo, z_hi = z_contact - 0.5 * p.contact_band_m, z_contact + 0.5 * p.contact_band_m

    def r_face(z):
        return r_tip_in - (z_tip - z) * tan_w

    base = _polygon([(b_i, 0.0), (b_o, 0.0), (b_o, z_b), (b_i, z_b)])
    # outer edge split at the strip ends, so the strips stop short of the steel
    tube_pts = [(r_i, z_b), (r_o, z_b)]
    if m > 0:
        tube_pts += [(r_o, z_b + m), (r_o, z_t - m)]
    tube_pts += [(r_o, z_t), (r_i, z_t)]
    tube = _polygon(tube_pts)
    collar = _polygon([(r_collar_in, z_t), (r_o, z_t), (r_o, z_c), (r_collar_in, z_c)])
    wedge = _polygon([(r_wedge_in, z_c), (r_o, z_c), (r_o, z_tip), (r_tip_in, z_tip),
                      (r_face(z_hi), z_hi), (r_face(z_lo), z_lo)])
    gmsh.model.occ.fragment([(2, s) for s in (base, tube, collar, wedge)], [])
    gmsh.model.occ.synchronize()
    surfaces = [t for _, t in gmsh.model.getEntities(2)]
    cuts = [0.0]
    for lo, hi in [*p.strips().values(), *p.guards()]:
        cuts += [lo, hi]
    volumes = _revolve(surfaces, cuts)

    cells = {"base": [], "tube": [], "wedge": []}
    for _, v in volumes:
        z = gmsh.model.occ.getCenterOfMass(3, v)[2]
        cells["base" if z < z_b else "tube" if z < z_t else "wedge"].append(v)
    strips = p.strips()
    guards = p.guards()
    facets = {name: [] for name in ["inner", *strips, "guard", "contact", "tip", "bottom"]}
    tol = 1e-6 * r_o
    for _, f in gmsh.model.getBoundary(volumes, combined=True, oriented=False):
        r, theta, z = _face_sample(f)
        if abs(z) < tol:
            facets["bottom"].append(f)
        elif abs(z - z_tip) < tol:
            facets["tip"].append(f)
        elif abs(r - r_i) < tol and z_b < z < z_t:
            facets["inner"].append(f)
        elif abs(r - r_o) < tol and z_b + m < z < z_t - m:
            for name, arc in [*strips.items(), *(("guard", arc) for arc in guards)]:
                if _in_arc(theta, arc):
                    facets[name].append(f)
        elif z_lo < z < z_hi and abs(r - r_face(z)) < 1e-3 * r_o:
            facets["contact"].append(f)
    _add_groups(3, cells)
    _add_groups(2, facets)

    tip_curves = [c for _, c in gmsh.model.getEntities(1)
                  if abs(gmsh.model.getBoundingBox(1, c)[2] - z_tip) < tol
                  and abs(gmsh.model.getBoundingBox(1, c)[5] - z_tip) < tol]
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "EdgesList", tip_curves)
    field.setNumber(dist, "NumPointsPerCurve", 200)
    threshold = field.add("Threshold")
    field.setNumber(threshold, "InField", dist)
    field.setNumber(threshold, "SizeMin", p.tip_mesh_size_m)
    field.setNumber(threshold, "SizeMax", p.mesh_size_m)
    field.setNumber(threshold, "DistMin", p.contact_depth_m + p.contact_band_m)
    field.setNumber(threshold, "DistMax", 0.5 * p.wedge_height_m + p.contact_depth_m)
    field.setAsBackgroundMesh(threshold)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", p.mesh_size_m)
    gmsh.model.mesh.generate(3)
    _reset_size_options()


def _reset_size_options() -> None:
    """gmsh stays initialised between models: put the global size options back to their defaults."""
    for name, value in (("Mesh.MeshSizeExtendFromBoundary", 1), ("Mesh.MeshSizeFromPoints", 1),
                        ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.MeshSizeMax", 1e22), ("Mesh.Algorithm", 6),
                        ("Mesh.RecombineAll", 0), ("Mesh.RecombinationAlgorithm", 1)):
        gmsh.option.setNumber(name, value)


def _plane_polygon(points_rz) -> int:
    """Plane surface in the plane x = r, y = z from an (r, z) polygon (consecutive duplicates dropped)."""
    occ = gmsh.model.occ
    pts = [pt for i, pt in enumerate(points_rz) if i == 0 or pt != points_rz[i - 1]]
    if pts[-1] == pts[0]:
        pts = pts[:-1]
    tags = [occ.addPoint(r, z, 0.0) for r, z in pts]
    lines = [occ.addLine(tags[i], tags[(i + 1) % len(tags)]) for i in range(len(tags))]
    return occ.addPlaneSurface([occ.addCurveLoop(lines)])


def _wedge_root_fillet(corner_rz, face_angle_deg: float, radius: float) -> int:
    """Fillet surface in the re-entrant corner between the collar's top (going -r) and the wedge's inner
    face (going up, ``face_angle_deg`` off the axis towards +r): a circular arc tangent to both."""
    occ = gmsh.model.occ
    a = math.radians(face_angle_deg)
    d_top = np.array([-1.0, 0.0])
    d_face = np.array([math.sin(a), math.cos(a)])
    half = 0.5 * math.acos(float(d_top @ d_face))       # half the air angle (52.5 deg for a 15 deg face)
    corner = np.asarray(corner_rz, dtype=float)
    t1 = corner + radius / math.tan(half) * d_top
    t2 = corner + radius / math.tan(half) * d_face
    bisector = (d_top + d_face) / np.linalg.norm(d_top + d_face)
    centre = corner + radius / math.sin(half) * bisector
    p_c, p_1, p_2, p_o = (occ.addPoint(x, y, 0.0) for x, y in (corner, t1, t2, centre))
    loop = occ.addCurveLoop([occ.addLine(p_1, p_c), occ.addLine(p_c, p_2), occ.addCircleArc(p_2, p_o, p_1)])
    surface = occ.addPlaneSurface([loop])
    occ.remove([(0, p_o)])              # the arc's centre: not part of the profile (a stray node breaks the mesh)
    return surface


def _profile_model(p: StatorParameters) -> tuple[dict[str, list[int]], dict[str, list[int]]]:
    """Mesh the stator's (r, z) profile in the current gmsh model (plane x = r, y = z). Returns the cell
    groups (surfaces) and the curve groups: 'inner_wall', 'ground_internal' (internal ground electrodes),
    'drive' (the outer wall's and the internal drive electrodes' extent), 'contact', 'tip', 'bottom'."""
    occ = gmsh.model.occ
    b_i, b_o, r_i, r_o = p.radii()
    z_b = p.base_height_m
    z_t = z_b + p.tube_height_m
    z_c = z_t + p.collar_height_m
    z_tip = p.tip_z_m
    tan_w = math.tan(math.radians(p.wedge_angle_deg))
    r_tip_in = r_o - p.tip_width_m
    r_wedge_in = r_o - p.wedge_base_width_m
    r_collar_in = min(r_i, r_wedge_in)
    m = p.electrode_margin_m
    _, z_contact = p.contact_point()
    z_lo, z_hi = z_contact - 0.5 * p.contact_band_m, z_contact + 0.5 * p.contact_band_m
    radii = p.tube_radii()

    def r_face(z):
        return r_tip_in - (z_tip - z) * tan_w

    wall_z = [z_b, z_b + m, z_t - m, z_t]
    outer_z = list(wall_z)
    if p.sensor_height_m is not None:
        top = z_t - m
        outer_z += [top - p.sensor_height_m, top - p.sensor_height_m - p.sensor_gap_m]
    outer_z = sorted(set(outer_z))
    surfaces = [_plane_polygon([(b_i, 0.0), (b_o, 0.0), (b_o, z_b), (b_i, z_b)])]
    for k in range(1, len(radii)):
        right = outer_z if k == len(radii) - 1 else wall_z
        pts = [(radii[k - 1], z_b)] + [(radii[k], z) for z in right] + [(radii[k - 1], z) for z in wall_z[::-1]]
        surfaces.append(_plane_polygon(pts))
    surfaces.append(_plane_polygon([(r_collar_in, z_t), (r_o, z_t), (r_o, z_c), (r_collar_in, z_c)]))
    surfaces.append(_plane_polygon([(r_wedge_in, z_c), (r_o, z_c), (r_o, z_tip), (r_tip_in, z_tip),
                                    (r_face(z_hi), z_hi), (r_face(z_lo), z_lo)]))
    corner = None
    if r_wedge_in > r_collar_in + 1e-9:
        corner = (r_wedge_in, z_c)
        if p.wedge_root_fillet_m > 0:
            surfaces.append(_wedge_root_fillet(corner, p.wedge_angle_deg, p.wedge_root_fillet_m))
    occ.fragment([(2, t) for t in surfaces], [])
    occ.removeAllDuplicates()
    occ.synchronize()

    cells = {"base": [], "tube": [], "tube_reversed": [], "wedge": []}
    for _, tag in gmsh.model.getEntities(2):
        r, z, _ = occ.getCenterOfMass(2, tag)
        if z < z_b:
            cells["base"].append(tag)
        elif z < z_t:
            layer = int(np.searchsorted(radii, r))           # 1 .. tube_layers
            cells["tube" if layer % 2 else "tube_reversed"].append(tag)
        else:
            cells["wedge"].append(tag)
    curves = {"inner_wall": [], "ground_internal": [], "drive": [], "contact": [], "tip": [], "bottom": []}
    tol = 1e-6 * r_o
    for _, tag in gmsh.model.getEntities(1):
        lo, hi = gmsh.model.getParametrizationBounds(1, tag)
        x0, y0, _, r, z, _, x1, y1, _ = gmsh.model.getValue(1, tag, [lo[0], 0.5 * (lo[0] + hi[0]), hi[0]])
        vertical = abs(x1 - x0) < tol
        if abs(y1) < tol and abs(y0) < tol:
            curves["bottom"].append(tag)
        elif abs(y0 - z_tip) < tol and abs(y1 - z_tip) < tol:
            curves["tip"].append(tag)
        elif vertical and abs(r - r_i) < tol and z_b < z < z_t:
            curves["inner_wall"].append(tag)
        elif vertical and z_b + m < z < z_t - m and any(abs(r - rk) < tol for rk in radii[1:]):
            k = min(range(1, len(radii)), key=lambda j: abs(r - radii[j]))
            curves["drive" if k % 2 else "ground_internal"].append(tag)
        elif z_lo < z < z_hi and abs(r - r_face(z)) < 1e-3 * r_o:
            curves["contact"].append(tag)

    h, h_tip, _ = p.sizes()
    field = gmsh.model.mesh.field
    tip_curves = curves["tip"]
    dist = field.add("Distance")
    field.setNumbers(dist, "EdgesList", tip_curves)
    field.setNumber(dist, "NumPointsPerCurve", 200)
    tip = field.add("Threshold")
    field.setNumber(tip, "InField", dist)
    field.setNumber(tip, "SizeMin", h_tip)
    field.setNumber(tip, "SizeMax", h)
    field.setNumber(tip, "DistMin", p.contact_depth_m + p.contact_band_m)
    field.setNumber(tip, "DistMax", 0.5 * p.wedge_height_m + p.contact_depth_m)
    # the wedge root (a re-entrant corner or its fillet) and the ends of the outer electrodes (the potential's
    # edge singularity) at the tip size, growing to the global size over 1 mm
    wanted = [(r_o, z_b + m), (r_o, z_t - m)] + ([corner] if corner is not None else [])
    spots = []
    for _, tag in gmsh.model.getEntities(0):
        x, y, _ = gmsh.model.getValue(0, tag, [])
        if any(abs(x - a) < tol and abs(y - b) < tol for a, b in wanted):
            spots.append(tag)
    spot_dist = field.add("Distance")
    field.setNumbers(spot_dist, "NodesList", spots)
    spot = field.add("Threshold")
    field.setNumber(spot, "InField", spot_dist)
    field.setNumber(spot, "SizeMin", h_tip)
    field.setNumber(spot, "SizeMax", h)
    field.setNumber(spot, "DistMin", max(p.wedge_root_fillet_m, 2 * h_tip))
    field.setNumber(spot, "DistMax", max(p.wedge_root_fillet_m, 2 * h_tip) + 0.001)
    both = field.add("Min")
    field.setNumbers(both, "FieldsList", [tip, spot])
    field.setAsBackgroundMesh(both)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)
    if p.profile_cells == "quadrilaterals":       # triangles recombined into quadrilaterals only ("simple full-quad")
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)
    gmsh.model.mesh.generate(2)
    _reset_size_options()
    return {k: v for k, v in cells.items() if v}, curves


def _fourier_groups(cells: dict[str, list[int]], curves: dict[str, list[int]]) -> None:
    """Physical groups of the profile mesh as a Fourier model's mesh: the cell groups, and facets 'inner'
    (every ground electrode), 'outer' (every drive electrode, whole circumference), 'contact', 'tip', 'bottom'."""
    _add_groups(2, cells)
    _add_groups(1, {"inner": curves["inner_wall"] + curves["ground_internal"], "outer": curves["drive"],
                    "contact": curves["contact"], "tip": curves["tip"], "bottom": curves["bottom"]})


def _swept_model(p: StatorParameters) -> None:
    """Replace the current gmsh model's profile mesh by its revolution in layers (a discrete 3D model)."""
    from geometry.revolution import add_discrete_model, layer_angles, profile_from_gmsh, sweep

    cells, curves = _profile_model(p)
    profile = profile_from_gmsh(cells, curves)
    _, _, r_i, r_o = p.radii()
    cuts = []
    for lo, hi in [*p.segments().values(), *p.sensor_patches().values()]:
        cuts += [lo, hi]
    # a sector starts on strip A1's lower edge: one pitch is then exactly one period of the whole mesh
    start = -0.5 * p.strip_width_deg
    sector = None if p.sector_deg is None else (start, start + p.sector_deg)
    angles, mirrored = layer_angles(cuts, p.sizes()[2], r_o, sector)
    if not p.alternate_layers:
        mirrored[:] = False

    def facet_name(group, r, z, theta):
        if group in ("contact", "tip", "bottom"):
            return group
        if group in ("inner_wall", "ground_internal"):
            return "inner"
        return p.drive_facet_name(theta % 360.0, z, outer=abs(r - r_o) < 1e-6 * r_o)

    mesh = sweep(profile, angles, facet_name, p.geometry_degree, mirrored,
                 None if sector is None else math.radians(sector[1]))
    gmsh.model.remove()
    gmsh.model.add("stator_swept")
    add_discrete_model(mesh, p.facet_names_3d())


def build_stator(comm: MPI.Comm, params: StatorParameters, kind: str) -> MeshData:
    if kind not in ("3d", "fourier"):
        raise ValueError(f"stator builder supports 3d and fourier, not {kind}")
    with GmshSession(comm, "stator"):
        if comm.rank == 0:
            if kind == "fourier":
                _fourier_groups(*_profile_model(params))
            elif params.mesh_method == "swept":
                _swept_model(params)
            else:
                _stator_model(params)
        return from_gmsh_model(comm, 2 if kind == "fourier" else 3)


def build_thin_ring(comm: MPI.Comm, params: ThinRingParameters, kind: str) -> MeshData:
    """Rectangular-section ring (cell ``ring``; facets ``inner``, ``outer``, ``top``, ``bottom``): 3D, or its
    (r, z) section for a Fourier model."""
    if kind not in ("3d", "fourier"):
        raise ValueError(f"thin_ring builder supports 3d and fourier, not {kind}")
    R, t, h = params.mean_radius_m, params.radial_thickness_m, params.axial_height_m
    r_i, r_o = R - 0.5 * t, R + 0.5 * t
    with GmshSession(comm, "thin_ring"):
        if comm.rank == 0 and kind == "fourier":
            surface = _plane_polygon([(r_i, 0.0), (r_o, 0.0), (r_o, h), (r_i, h)])
            gmsh.model.occ.synchronize()
            facets = {"inner": [], "outer": [], "top": [], "bottom": []}
            tol = 1e-6 * R
            for _, line in gmsh.model.getEntities(1):
                lo, hi = gmsh.model.getParametrizationBounds(1, line)
                x0, y0, _, x1, y1, _ = gmsh.model.getValue(1, line, [lo[0], hi[0]])
                name = ("bottom" if max(abs(y0), abs(y1)) < tol else "top" if max(abs(y0 - h), abs(y1 - h)) < tol
                        else "inner" if x1 < R else "outer")
                facets[name].append(line)
            _add_groups(2, {"ring": [surface]})
            _add_groups(1, facets)
            gmsh.option.setNumber("Mesh.MeshSizeMax", params.mesh_size_m)
            gmsh.model.mesh.generate(2)
            _reset_size_options()
        elif comm.rank == 0:
            surface = _polygon([(r_i, 0.0), (r_o, 0.0), (r_o, h), (r_i, h)])
            gmsh.model.occ.synchronize()
            pieces = params.angular_pieces
            volumes = _revolve([surface], [360.0 * k / pieces for k in range(pieces)])
            facets = {"inner": [], "outer": [], "top": [], "bottom": []}
            tol = 1e-6 * R
            for _, f in gmsh.model.getBoundary(volumes, combined=True, oriented=False):
                r, _, z = _face_sample(f)
                name = ("bottom" if abs(z) < tol else "top" if abs(z - h) < tol
                        else "inner" if r < R else "outer")
                facets[name].append(f)
            _add_groups(3, {"ring": [v for _, v in volumes]})
            _add_groups(2, facets)
            gmsh.option.setNumber("Mesh.MeshSizeMax", params.mesh_size_m)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
            gmsh.model.mesh.generate(3)
            _reset_size_options()
        return from_gmsh_model(comm, 3)
