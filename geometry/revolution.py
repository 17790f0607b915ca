"""Meshes of bodies of revolution about z from one (r, z) profile mesh.

The profile is meshed once in 2D (gmsh triangles or quadrilaterals in the plane x = r, y = z). The same
cells are either the mesh of a Fourier-harmonic model (``model = "fourier"``, exact in theta) or are
revolved into a 3D mesh of structured layers round the axis ("swept" mesh). A quadrilateral sweeps a
hexahedron per layer. A triangle sweeps a prism, cut into three tetrahedra by a rule that depends on the
profile node numbers only (on the quadrilateral side between profile nodes p < q the diagonal runs from
p's lower copy to q's upper copy), so neighbouring prisms share their diagonals and every layer is the
same pattern rotated:
with equal layers per 22.5 deg the mesh is invariant under the stator's 16-fold rotation, and the
n = 4 pair is degenerate but for the physics (floating electrodes). The 3D mesh is handed to dolfinx
through a discrete gmsh model, so cell and facet groups travel by name as for every other builder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gmsh
import numpy as np


@dataclass
class ProfileMesh:
    """A meshed (r, z) profile: nodes, cells (triangles or quadrilaterals, counterclockwise) with their cell
    group, and the boundary or interface edges of the named curve groups (each edge with its group)."""

    rz: np.ndarray                      # (n_nodes, 2) [m]
    cells: np.ndarray                   # (n_cells, 3 or 4) node indices
    cell_group: np.ndarray              # (n_cells,) index into cell_names
    cell_names: list[str]
    edges: np.ndarray                   # (n_edges, 2) node indices
    edge_group: np.ndarray              # (n_edges,) index into edge_names
    edge_names: list[str] = field(default_factory=list)


def profile_from_gmsh(cell_groups: dict[str, list[int]], curve_groups: dict[str, list[int]]) -> ProfileMesh:
    """Arrays of the current (meshed, 2D, plane x = r, y = z) gmsh model: the cells of the surfaces in
    ``cell_groups`` (all 3-node triangles or all 4-node quadrilaterals), line elements of the curves in
    ``curve_groups``."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    order = np.argsort(tags)
    tags = np.asarray(tags)[order]
    xyz = np.asarray(coords).reshape(-1, 3)[order]
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags] = np.arange(tags.size)
    triangles, groups = [], []
    cell_names = list(cell_groups)
    for g, name in enumerate(cell_names):
        for surface in cell_groups[name]:
            types, _, nodes = gmsh.model.mesh.getElements(2, surface)
            for etype, enodes in zip(types, nodes):
                if etype not in (2, 3):
                    raise RuntimeError(f"profile surface {surface} has element type {etype}, not 3-node triangles "
                                       f"or 4-node quadrilaterals")
                tri = index[np.asarray(enodes, dtype=np.int64).reshape(-1, 3 if etype == 2 else 4)]
                triangles.append(tri)
                groups.append(np.full(tri.shape[0], g, dtype=np.int32))
    if len({t.shape[1] for t in triangles}) > 1:
        raise RuntimeError("the profile mixes triangles and quadrilaterals")
    edges, edge_groups = [], []
    edge_names = list(curve_groups)
    for g, name in enumerate(edge_names):
        for curve in curve_groups[name]:
            types, _, nodes = gmsh.model.mesh.getElements(1, curve)
            for etype, enodes in zip(types, nodes):
                if etype != 1:
                    raise RuntimeError(f"profile curve {curve} has element type {etype}, not 2-node lines")
                e = index[np.asarray(enodes, dtype=np.int64).reshape(-1, 2)]
                edges.append(e)
                edge_groups.append(np.full(e.shape[0], g, dtype=np.int32))
    used = np.unique(np.concatenate(triangles))
    renumber = np.full(tags.size, -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    tri = renumber[np.concatenate(triangles)]
    edge_array = renumber[np.concatenate(edges)] if edges else np.zeros((0, 2), dtype=np.int64)
    return ProfileMesh(xyz[used, :2].copy(), tri, np.concatenate(groups), cell_names, edge_array,
                       np.concatenate(edge_groups) if edge_groups else np.zeros(0, dtype=np.int32), edge_names)


def layer_angles(cuts_deg: list[float], arc_size_m: float, radius_m: float,
                 sector_deg: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Layer boundaries [rad] round the axis: every cut angle is a boundary; the piece between two
    consecutive cuts gets round(arc length at ``radius_m`` / ``arc_size_m``) equal layers (at least one).
    Returns the n_layers start angles, increasing from the first cut (a turn in all; or over the
    ``sector_deg`` (start, end) only, whose ends are cuts too), and for each layer whether it is mirrored
    (every second layer of a piece, counted from the piece's start: see sweep)."""
    if sector_deg is not None:
        start, end = sector_deg
        cuts = sorted({start, end} | {c + 360.0 * k for c in cuts_deg for k in (-1, 0, 1)
                                      if start < c + 360.0 * k < end})
    else:
        cuts = sorted({round(c % 360.0, 9) for c in cuts_deg}) or [0.0]
        cuts.append(cuts[0] + 360.0)
    angles, mirrored = [], []
    for a, b in zip(cuts[:-1], cuts[1:]):
        n = max(1, int(round(math.radians(b - a) * radius_m / arc_size_m)))
        angles += list(np.linspace(a, b, n, endpoint=False))
        mirrored += [k % 2 == 1 for k in range(n)]
    return np.radians(np.asarray(angles)), np.asarray(mirrored)


@dataclass
class SweptMesh:
    """Cells of a profile revolved in layers, and its named boundary facets: tetrahedra and triangles (4 and 3
    nodes, or quadratic: 10 and 6, in gmsh's node order: vertices, then the edge nodes 01, 12, 02, 03, 23, 13
    of a tetrahedron and 01, 12, 02 of a triangle), or hexahedra and quadrilaterals (8 and 4 nodes)."""

    xyz: np.ndarray          # (n_nodes, 3)
    tets: np.ndarray         # (n_cells, 4, 10 or 8)
    tet_group: np.ndarray    # (n_cells,) index into cell_names
    cell_names: list[str]
    triangles: np.ndarray    # (n_facets, 3, 6 or 4)
    triangle_names: list[str]   # one name per facet

    @property
    def degree(self) -> int:
        return 2 if self.tets.shape[1] == 10 else 1

    @property
    def gmsh_types(self) -> tuple[int, int]:
        """gmsh element types of the cells and the facets."""
        return {4: (4, 2), 10: (11, 9), 8: (5, 3)}[self.tets.shape[1]]


def _profile_edges(triangles: np.ndarray, n_p: int) -> tuple[np.ndarray, callable]:
    """Unique edges (p < q) of the profile triangles and a lookup (p, q arrays) -> edge index."""
    pairs = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [0, 2]]])
    pairs = np.sort(pairs, axis=1)
    keys = np.unique(pairs[:, 0] * n_p + pairs[:, 1])

    def lookup(p, q):
        lo, hi = np.minimum(p, q), np.maximum(p, q)
        index = np.searchsorted(keys, lo * n_p + hi)
        if not np.array_equal(keys[np.minimum(index, keys.size - 1)], lo * n_p + hi):
            raise RuntimeError("an edge is not an edge of the profile triangles")
        return index

    return np.column_stack([keys // n_p, keys % n_p]), lookup


def sweep(profile: ProfileMesh, angles: np.ndarray, facet_name, degree: int = 1,
          mirrored: np.ndarray | None = None, end_angle: float | None = None) -> SweptMesh:
    """Revolve ``profile`` through the layers starting at ``angles`` [rad]: the last one closes on the first
    (a whole turn), or, given ``end_angle``, ends there (a sector: its two end faces are copies of the profile
    mesh). ``facet_name(group, r_mid, z_mid, theta_mid_deg)`` names the two triangles that a profile edge
    of curve group ``group`` sweeps in one layer (or returns None: not a named facet).

    In a ``mirrored`` layer the prisms are cut the other way round (the side diagonals from p's upper to q's
    lower copy): alternating layers keep the cut pattern from leaning one way round the axis.

    ``degree`` 2 gives quadratic (curved) cells: the edge nodes lie at the parameter midpoints of the
    revolution (r, z, theta) -> (r cos theta, r sin theta, z), so the 3D mesh is the revolution of the
    profile mesh up to the quadratic interpolation of the circles (an error of order dtheta^3 in position),
    not a polygon of chords (order dtheta^2)."""
    n_p = profile.rz.shape[0]
    n_l = angles.size
    r, z = profile.rz[:, 0], profile.rz[:, 1]
    theta = np.append(angles, angles[0] + 2 * math.pi if end_angle is None else end_angle)
    mid_theta = 0.5 * (theta[:-1] + theta[1:])
    n_planes = n_l if end_angle is None else n_l + 1        # node planes; layer l runs from plane l to l + 1
    if end_angle is not None and (degree != 1 or profile.cells.shape[1] != 3):
        raise ValueError("a sector is swept from triangles into straight-sided tetrahedra only")

    def place(rr, zz, tt):
        return np.column_stack([np.outer(np.cos(tt), rr).ravel(), np.outer(np.sin(tt), rr).ravel(),
                                np.tile(zz, tt.size)])

    xyz = [place(r, z, theta[:n_planes])]
    if profile.cells.shape[1] == 4:
        if degree != 1:
            raise ValueError("quadrilateral profiles sweep into straight-sided hexahedra only (degree 1)")
        return _sweep_quadrilaterals(profile, angles, facet_name, mid_theta)
    tri = np.sort(profile.cells, axis=1)
    i, j, k = tri[:, 0], tri[:, 1], tri[:, 2]
    if degree == 2:
        edges, edge_of = _profile_edges(tri, n_p)
        n_e = edges.shape[0]
        r_e, z_e = 0.5 * (r[edges[:, 0]] + r[edges[:, 1]]), 0.5 * (z[edges[:, 0]] + z[edges[:, 1]])
        base_profile = n_l * n_p                   # edge nodes of profile edges, per layer
        base_theta = base_profile + n_l * n_e      # of a node's circle arc between layers l and l + 1
        base_diag = base_theta + n_l * n_p         # of the side diagonal (p, l)-(q, l + 1), p < q
        xyz += [place(r_e, z_e, angles), place(r, z, mid_theta), place(r_e, z_e, mid_theta)]
        e_ij, e_jk, e_ik = edge_of(i, j), edge_of(j, k), edge_of(i, k)
    elif degree != 1:
        raise ValueError(f"degree {degree}")
    if mirrored is None:
        mirrored = np.zeros(n_l, dtype=bool)
    tets, groups = [], []
    for layer in range(n_l):
        lo, hi = layer * n_p, ((layer + 1) % n_planes) * n_p
        up = (layer + 1) % n_l
        if degree == 2:
            prof_lo, prof_hi = base_profile + layer * n_e, base_profile + up * n_e
            arc, diag = base_theta + layer * n_p, base_diag + layer * n_e
        if mirrored[layer]:                 # the same cut with the layer's two faces swapped
            lo, hi = hi, lo
            if degree == 2:
                prof_lo, prof_hi = prof_hi, prof_lo
        # diagonal of each side quad (p < q): p's lower copy to q's upper copy
        cells = [np.column_stack([i + lo, j + lo, k + lo, k + hi]),
                 np.column_stack([i + lo, j + lo, j + hi, k + hi]),
                 np.column_stack([i + lo, i + hi, j + hi, k + hi])]
        if degree == 2:
            cells[0] = np.column_stack([cells[0], prof_lo + e_ij, prof_lo + e_jk, prof_lo + e_ik, diag + e_ik,
                                        arc + k, diag + e_jk])
            cells[1] = np.column_stack([cells[1], prof_lo + e_ij, arc + j, diag + e_ij, diag + e_ik,
                                        prof_hi + e_jk, diag + e_jk])
            cells[2] = np.column_stack([cells[2], arc + i, prof_hi + e_ij, diag + e_ij, diag + e_ik,
                                        prof_hi + e_jk, prof_hi + e_ik])
        tets += cells
        groups += [profile.cell_group] * 3
    bedges = np.sort(profile.edges, axis=1)
    mid = 0.5 * (profile.rz[bedges[:, 0]] + profile.rz[bedges[:, 1]])
    b_index = edge_of(bedges[:, 0], bedges[:, 1]) if degree == 2 else None
    facets, names = [], []
    for layer in range(n_l):
        lo, hi = layer * n_p, ((layer + 1) % n_planes) * n_p
        up = (layer + 1) % n_l
        flip = bool(mirrored[layer])
        if flip:
            lo, hi = hi, lo
        theta_mid = math.degrees(mid_theta[layer])
        for e, (p, q) in enumerate(bedges):
            name = facet_name(profile.edge_names[profile.edge_group[e]], mid[e, 0], mid[e, 1], theta_mid)
            if name is None:
                continue
            if degree == 2:
                pe_lo, pe_hi = base_profile + layer * n_e + b_index[e], base_profile + up * n_e + b_index[e]
                if flip:
                    pe_lo, pe_hi = pe_hi, pe_lo
                arc_p, arc_q = base_theta + layer * n_p + p, base_theta + layer * n_p + q
                dg = base_diag + layer * n_e + b_index[e]
                facets += [(p + lo, q + lo, q + hi, pe_lo, arc_q, dg), (p + lo, q + hi, p + hi, dg, pe_hi, arc_p)]
            else:
                facets += [(p + lo, q + lo, q + hi), (p + lo, q + hi, p + hi)]
            names += [name, name]
    width = 6 if degree == 2 else 3
    return SweptMesh(np.concatenate(xyz), np.concatenate(tets), np.concatenate(groups), list(profile.cell_names),
                     np.asarray(facets, dtype=np.int64).reshape(-1, width), names)


def _sweep_quadrilaterals(profile: ProfileMesh, angles: np.ndarray, facet_name, mid_theta) -> SweptMesh:
    """Hexahedra of a quadrilateral profile revolved in layers (gmsh order: the lower quadrilateral, then
    the upper one), and the quadrilateral facets its named edges sweep."""
    n_p, n_l = profile.rz.shape[0], angles.size
    r, z = profile.rz[:, 0], profile.rz[:, 1]
    xyz = np.column_stack([np.outer(np.cos(angles), r).ravel(), np.outer(np.sin(angles), r).ravel(),
                           np.tile(z, n_l)])
    quads = profile.cells.copy()
    corner = profile.rz[quads]                  # orient every quadrilateral clockwise in (r, z): with the layer
    area = np.einsum("ij,ij->i", corner[:, :, 0], np.roll(corner[:, :, 1], -1, axis=1)) - np.einsum(
        "ij,ij->i", np.roll(corner[:, :, 0], -1, axis=1), corner[:, :, 1])   # along +theta the hexahedra are
    quads[area > 0] = quads[area > 0, ::-1]                                     # then right-handed
    cells, groups = [], []
    for layer in range(n_l):
        lo, hi = layer * n_p, ((layer + 1) % n_l) * n_p
        cells.append(np.column_stack([quads + lo, quads + hi]))
        groups.append(profile.cell_group)
    edges = profile.edges
    mid = 0.5 * (profile.rz[edges[:, 0]] + profile.rz[edges[:, 1]])
    facets, names = [], []
    for layer in range(n_l):
        lo, hi = layer * n_p, ((layer + 1) % n_l) * n_p
        theta_mid = math.degrees(mid_theta[layer])
        for e, (p, q) in enumerate(edges):
            name = facet_name(profile.edge_names[profile.edge_group[e]], mid[e, 0], mid[e, 1], theta_mid)
            if name is not None:
                facets.append((p + lo, q + lo, q + hi, p + hi))
                names.append(name)
    return SweptMesh(xyz, np.concatenate(cells), np.concatenate(groups), list(profile.cell_names),
                     np.asarray(facets, dtype=np.int64).reshape(-1, 4), names)


def add_discrete_model(mesh: SweptMesh, facet_order: list[str]) -> None:
    """The swept mesh as a discrete gmsh model (current model, rank 0): one volume per cell group, one
    surface per facet name (in ``facet_order``, names without facets skipped), named physical groups."""
    model = gmsh.model
    volumes = {name: model.addDiscreteEntity(3) for name in mesh.cell_names}
    first = volumes[mesh.cell_names[0]]
    node_tags = np.arange(1, mesh.xyz.shape[0] + 1, dtype=np.int64)
    model.mesh.addNodes(3, first, node_tags, mesh.xyz.ravel())
    next_tag = 1
    for g, name in enumerate(mesh.cell_names):
        tets = mesh.tets[mesh.tet_group == g]
        if not tets.size:
            continue
        tags = np.arange(next_tag, next_tag + tets.shape[0], dtype=np.int64)
        next_tag += tets.shape[0]
        model.mesh.addElementsByType(volumes[name], mesh.gmsh_types[0], tags, (tets + 1).ravel())
    names = np.asarray(mesh.triangle_names, dtype=object)
    surfaces = {}
    for name in facet_order:
        rows = mesh.triangles[names == name] if names.size else np.zeros((0, mesh.triangles.shape[1]), dtype=np.int64)
        if not rows.size:
            continue
        surfaces[name] = model.addDiscreteEntity(2)
        tags = np.arange(next_tag, next_tag + rows.shape[0], dtype=np.int64)
        next_tag += rows.shape[0]
        model.mesh.addElementsByType(surfaces[name], mesh.gmsh_types[1], tags, (rows + 1).ravel())
    for tag, name in enumerate(mesh.cell_names, start=1):
        if (mesh.tet_group == tag - 1).any():
            model.addPhysicalGroup(3, [volumes[name]], tag)
            model.setPhysicalName(3, tag, name)
    for tag, (name, surface) in enumerate(surfaces.items(), start=1):
        model.addPhysicalGroup(2, [surface], tag)
        model.setPhysicalName(2, tag, name)
