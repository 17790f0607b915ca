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

import gmsh
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
    tip_mesh_size_m: float = param(0.0005, gt=0, doc="element size at the wedge tip")

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
                        ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.MeshSizeMax", 1e22)):
        gmsh.option.setNumber(name, value)


def build_stator(comm: MPI.Comm, params: StatorParameters, kind: str) -> MeshData:
    if kind != "3d":
        raise ValueError(f"stator builder supports 3d, not {kind}")
    with GmshSession(comm, "stator"):
        if comm.rank == 0:
            _stator_model(params)
        return from_gmsh_model(comm, 3)


def build_thin_ring(comm: MPI.Comm, params: ThinRingParameters, kind: str) -> MeshData:
    """Rectangular-section ring (cell ``ring``; facets ``inner``, ``outer``, ``top``, ``bottom``)."""
    if kind != "3d":
        raise ValueError(f"thin_ring builder supports 3d, not {kind}")
    R, t, h = params.mean_radius_m, params.radial_thickness_m, params.axial_height_m
    r_i, r_o = R - 0.5 * t, R + 0.5 * t
    with GmshSession(comm, "thin_ring"):
        if comm.rank == 0:
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
