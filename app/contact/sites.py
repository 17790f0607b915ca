"""Where a contact acts on a reduced structure: its sites (points, areas, frames) and the structure's DOFs it
keeps as Craig-Bampton interface coordinates.

The FE tier integrates a surface contact's penalty over its facets at quadrature points. The modal tier
evaluates the same law at *sites*, each carrying an area, whose displacement is a row block of the reduced
basis, y = R q (app/reduced/loop_kernel.py):

* ``sampling = "nodes"`` (the default): every node of the facet group is a site, with its lumped area (the
  consistent nodal force of a uniform pressure, app/reduced/surface.py); the nodes' DOFs are interface
  coordinates (``reduction.interface_nodes = 0``: all of them), so a site's row is a unit row.
* ``sampling = "ring"``: a surface of revolution about the obstacle's axis (a cone, or a body spinning about
  that axis) touched along a circle: ``sample_points`` sites evenly round the contact circle (a cone: where
  the obstacle's face has its ``radius_m``, at the body's reference point), each carrying the facet group's
  area over their number. ``reduction.interface_nodes`` of the group's nodes, nearest to as many targets
  evenly round that circle, are interface coordinates. A site's row is, with ``reduction.site_displacement``,
  ``"interface"``: interpolated from the interface nodes (periodic Lagrange, cubic, in angle, in cylindrical
  components: loads act only on interface coordinates, whose static response the constraint modes hold
  exactly), or ``"field"``: the reduced field itself at the point (every basis vector evaluated there).

A node contact's site is its node (its DOFs interface coordinates, unit rows). Every site also has a frame
for its diagnostics: n (the obstacle's normal), e1 (along the body's spin, else a tangent), e2 = n x e1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from app.errors import CaseError

RING_INTERPOLATION_ORDER = 3


@dataclass
class SiteSet:
    """The sites of one contact, before reduction: reference points, areas, and how their rows are formed."""

    contact: int                          # index of the contact in the case's list
    name: str
    points_m: np.ndarray                  # (n, 3) reference positions
    weight: np.ndarray                    # (n,) areas [m^2] (1 for a node contact)
    interface_dofs: np.ndarray            # (k, gdim) global DOFs of the interface nodes (-1 where held)
    node_dofs: np.ndarray | None = None   # sites at FE nodes: (n, gdim) their global DOFs (-1 held)
    ring: dict | None = None              # ring sampling: axis, centre, node angles, site angles, rule
    extra: dict = field(default_factory=dict)


def contact_circle(section, case, body) -> tuple[np.ndarray, np.ndarray, float]:
    """(axis a, centre c, radius R) of the contact circle of a ring-sampled surface contact: the obstacle's
    cone axis through the body's reference point, radius its radius_m there; or, for a plane or sphere on a
    body that spins about one axis, that axis and the mean radius of the surface's nodes (set by the caller)."""
    position = np.zeros(3)
    position[: len(body.position_m)] = body.position_m
    if section.shape == "cone":
        axis = np.asarray(section.axis, dtype=float)
        return axis / np.linalg.norm(axis), position, float(section.radius_m)
    axes = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    if len(body.rotations) != 1 or body.rotations[0].axis not in axes:
        raise CaseError(case.source, "transient.contacts.sampling",
                        "ring sampling needs a cone obstacle or a body that spins about one axis x, y or z")
    return np.asarray(axes[body.rotations[0].axis]), position, -1.0


def cylindrical_frames(angles: np.ndarray, e1: np.ndarray, e2: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rows e_r, e_theta, a at the given angles (e_r = cos t e1 + sin t e2)."""
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    e_r = c * e1 + s * e2
    e_t = -s * e1 + c * e2
    return np.stack([e_r, e_t, np.tile(axis, (angles.size, 1))], axis=1)


def in_plane_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors normal to ``axis`` (right-handed with it); for the z axis: e_x, e_y."""
    trial = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = trial - (trial @ axis) * axis
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def interpolation_stencil(node_angles: np.ndarray, point_angles: np.ndarray, order: int = RING_INTERPOLATION_ORDER):
    """Periodic Lagrange interpolation round a ring in angle: for each point, the ``order + 1`` nodes nearest
    it (half before, half after) and their weights, from the nodes' own (unevenly spaced) angles [rad]."""
    n_b = node_angles.size
    order_of = np.argsort(node_angles)
    theta = node_angles[order_of]
    width = order + 1
    idx = np.empty((point_angles.size, width), np.int64)
    weights = np.empty((point_angles.size, width))
    for c, phi in enumerate(point_angles % (2 * math.pi)):
        right = int(np.searchsorted(theta, phi, side="right"))
        ks = np.arange(right - (width + 1) // 2, right - (width + 1) // 2 + width)
        turns = np.floor_divide(ks, n_b)
        x = theta[ks % n_b] + 2 * math.pi * turns
        for s in range(width):
            others = np.delete(x, s)
            weights[c, s] = np.prod((phi - others) / (x[s] - others))
        idx[c] = order_of[ks % n_b]
    return idx, weights


def ring_heights(n_rings: int, h_lo: float, h_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Heights [m] along the axis of ``n_rings`` rings of sites across a band from ``h_lo`` to ``h_hi``, and their
    weights (summing to 1): Gauss-Legendre points of the band's height, as the FE tier's facet quadrature samples
    the band across it (docs/motor-rotor.md, "Sampling across the band")."""
    x, w = np.polynomial.legendre.leggauss(n_rings)
    # the ring nearest the band's middle first: its first site is the contact's probe (the contact point's path)
    order = np.argsort(np.abs(x), kind="stable")
    return 0.5 * (h_lo + h_hi) + 0.5 * (h_hi - h_lo) * x[order], 0.5 * w[order]


def ring_sites(contact_index: int, section, case, body, nodes, area_m2: float, n_points: int, n_interface: int,
               rule: str, prefix: str, band: bool = False, n_rings: int = 1) -> SiteSet:
    """Ring sampling of a surface contact (module docstring): ``nodes`` are the facet group's nodes
    (app/reduced/surface.py SurfaceNodes), ``area_m2`` its area. ``band``: the band interface
    (:func:`ring_band_patterns`): ``n_interface`` stations on each edge of the band (its lowest and highest
    nodes along the axis), the band and the sites interpolated cubically in angle and linearly in height.
    ``n_rings`` > 1 (a cone): that many rings of ``n_points`` sites across the band's height
    (:func:`ring_heights`), each on the cone at its height, each site carrying its ring's share of the area
    (weight x radius), ring-major order, the ring nearest the band's middle first."""
    file = case.source
    axis, centre, radius = contact_circle(section, case, body)
    e1, e2 = in_plane_basis(axis)
    xyz = np.zeros((nodes.size, 3))
    xyz[:, : nodes.coordinates_m.shape[1]] = nodes.coordinates_m
    rel = xyz - centre
    height = rel @ axis
    radial = rel - np.outer(height, axis)
    rho = np.linalg.norm(radial, axis=1)
    if radius < 0:                              # plane or sphere: the surface's mean radius and height
        radius = float(np.average(rho, weights=nodes.area_m2))
    h_c = 0.0 if section.shape == "cone" else float(np.average(height, weights=nodes.area_m2))
    angles_nodes = np.arctan2(radial @ e2, radial @ e1) % (2 * math.pi)
    k = n_interface
    if k > nodes.size:
        raise CaseError(file, "reduction.interface_nodes", f"the facet group of {prefix} has only {nodes.size} nodes")
    targets = (2 * math.pi * np.arange(k) / k)
    ring_angles = 2 * math.pi * (np.arange(n_points) + 0.5) / n_points
    h_lo, h_hi = float(height.min()), float(height.max())
    if band and h_hi - h_lo > 1e-9 * max(radius, 1e-30):
        # stations on both edges of the band: the band can tilt across its height, as the wave's bending tilts it
        chosen = []
        for level in (h_lo, h_hi):
            on_edge = np.flatnonzero(np.abs(height - level) <= 1e-3 * (h_hi - h_lo))
            gap = np.abs((angles_nodes[on_edge][None, :] - targets[:, None] + math.pi) % (2 * math.pi) - math.pi)
            chosen += [int(on_edge[i]) for i in np.argmin(gap, axis=1)]
        heights = np.array([h_lo, h_hi])

        def level_weights(h):
            upper = np.clip((np.asarray(h) - h_lo) / (h_hi - h_lo), 0.0, 1.0)
            return np.stack([1.0 - upper, upper], axis=-1)
    else:
        target_xyz = centre + h_c * axis + radius * (np.outer(np.cos(targets), e1) + np.outer(np.sin(targets), e2))
        chosen = [int(np.argmin(np.linalg.norm(xyz - t, axis=1))) for t in target_xyz]
        heights = np.array([h_c])

        def level_weights(h):
            return np.ones((np.size(h), 1))
    if len(set(chosen)) != len(chosen):
        raise CaseError(file, "reduction.interface_nodes", f"more interface nodes than {prefix}'s facet group has "
                                                           "round its contact circle: use fewer")
    if (nodes.global_dofs[chosen] < 0).any():
        raise CaseError(file, f"{prefix}.facets", "the contact surface touches a support")
    if n_rings == 1:
        ring_h, ring_r, ring_share = np.array([h_c]), np.array([radius]), np.ones(1)
    else:
        ring_h, ring_w = ring_heights(n_rings, h_lo, h_hi)
        # the cone's radius at each height (its radius grows along the axis); the area of a ring's slice of the
        # band grows with its radius
        ring_r = radius + ring_h * math.tan(math.radians(section.half_angle_deg))
        ring_share = ring_w * ring_r / float(ring_w @ ring_r)
    site_angles = np.tile(ring_angles, n_rings)
    site_h = np.repeat(ring_h, n_points)
    site_r = np.repeat(ring_r, n_points)
    points = centre + np.outer(site_h, axis) + site_r[:, None] * (np.outer(np.cos(site_angles), e1)
                                                                  + np.outer(np.sin(site_angles), e2))
    weight = np.repeat(ring_share, n_points) * area_m2 / n_points
    ring = {"axis": axis, "centre": centre, "e1": e1, "e2": e2, "node_angles": angles_nodes[chosen],
            "site_angles": site_angles, "rule": rule, "rings": n_rings,
            # stations: ``levels`` rings of k interface nodes (level-major), each point's weight per level
            "levels": heights.size, "site_level_weights": level_weights(site_h),
            # every node of the band, for the band interface (ring_band_patterns)
            "band_angles": angles_nodes, "band_dofs": nodes.global_dofs, "band_xyz": xyz,
            "band_level_weights": level_weights(height)}
    return SiteSet(contact_index, section.name, points, weight, nodes.global_dofs[chosen], None, ring)


def ring_interpolation(ring: dict, angles: np.ndarray, level_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ring's interpolation from its stations (interface nodes) at points given by their angles [rad] and
    weights per level of stations (n, levels): periodic cubic Lagrange in angle of the cylindrical components within
    each level, the level weights across levels (one level; two for the band interface, linear in height).
    Returns the stations each point uses (n, m; indices into ``ring["node_angles"]``) and the 3 x 3 blocks B
    (n, m, 3, 3) with u_point = sum_s B_s u_station, both in global components."""
    levels = ring.get("levels", 1)
    per_level = ring["node_angles"].size // levels
    point_frames = cylindrical_frames(angles, ring["e1"], ring["e2"], ring["axis"])
    stations, blocks = [], []
    for level in range(levels):
        node_angles = ring["node_angles"][level * per_level:(level + 1) * per_level]
        idx, weights = interpolation_stencil(node_angles, angles)
        weights = weights * level_weights[:, level:level + 1]
        node_frames = cylindrical_frames(node_angles, ring["e1"], ring["e2"], ring["axis"])
        # global at the point = F_p^T (cylindrical at the point) = F_p^T w F_s (global at station s)
        blocks.append(weights[:, :, None, None] * np.einsum("pji,psjk->psik", point_frames, node_frames[idx]))
        stations.append(idx + level * per_level)
    return np.concatenate(stations, axis=1), np.concatenate(blocks, axis=1)


def ring_interface_rows(ring: dict, n_interface_before: int, gdim: int, n_columns: int) -> np.ndarray:
    """Rows (n_sites * 3, n_columns) of the ring's sites interpolated from its interface nodes (whose
    coordinates start at ``n_interface_before``, gdim per node in component order): :func:`ring_interpolation`
    at the sites."""
    site_angles = ring["site_angles"]
    weights = ring.get("site_level_weights", np.ones((site_angles.size, 1)))
    stations, blocks = ring_interpolation(ring, site_angles, weights)
    n_sites, width = stations.shape
    rows = np.zeros((n_sites * 3, n_columns))
    site = np.arange(n_sites)[:, None, None, None]
    r = np.arange(3)[None, None, :, None]
    kk = np.arange(gdim)[None, None, None, :]
    columns = n_interface_before + gdim * stations[:, :, None, None] + kk
    np.add.at(rows, (3 * site + r, np.broadcast_to(columns, (n_sites, width, 3, gdim))), blocks[:, :, :, :gdim])
    return rows


def ring_band_patterns(ring: dict, interface_dofs: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """The band interface (``reduction.interface = "band"``): each interface coordinate of a ring, interface node k's
    global component c (its DOF ``interface_dofs[k, c]``), as a displacement pattern of every node of the contact
    band: node j moves by B_jk e_c, :func:`ring_interpolation` at the band's nodes, the sites' own interpolation.
    Returns {interface DOF: (global DOFs, values)}; held DOFs (-1) are left out. At an interface node the pattern is
    the unit displacement of that DOF (Lagrange weights), so the coordinate is still the node's displacement;
    between them the band follows the interpolation instead of being free, so the sites' forces act on the band as
    loads spread over it rather than as point loads on a few nodes, whose local compliance does not converge (3D:
    it grows like 1/h)."""
    band_dofs = ring["band_dofs"]
    gdim = band_dofs.shape[1]
    stations, blocks = ring_interpolation(ring, ring["band_angles"], ring["band_level_weights"])
    n_band, width = stations.shape
    # one entry per (band node j, stencil slot s, band component r, station component c)
    key = np.broadcast_to(interface_dofs[stations][:, :, None, :], (n_band, width, gdim, gdim))
    dof = np.broadcast_to(band_dofs[:, None, :, None], (n_band, width, gdim, gdim))
    value = blocks[:, :, :gdim, :gdim]
    keep = (key >= 0) & (dof >= 0) & (value != 0.0)
    key, dof, value = key[keep], dof[keep], value[keep]
    order = np.lexsort((dof, key))
    key, dof, value = key[order], dof[order], value[order]
    out = {}
    bounds = np.flatnonzero(np.diff(key)) + 1
    for k_slice in np.split(np.arange(key.size), bounds):
        if k_slice.size == 0:
            continue
        unique, inverse = np.unique(dof[k_slice], return_inverse=True)
        out[int(key[k_slice[0]])] = (unique, np.bincount(inverse, weights=value[k_slice], minlength=unique.size))
    return out


def site_frames(points: np.ndarray, normals: np.ndarray, spin_axis: np.ndarray | None, lever_origin: np.ndarray
                ) -> np.ndarray:
    """(n, 3, 3) diagnostics frames: n, e1 = unit(a x r) along the spin (or a tangent), e2 = n x e1."""
    frames = np.zeros((points.shape[0], 3, 3))
    for i, (x, n) in enumerate(zip(points, normals)):
        if spin_axis is not None:
            t = np.cross(spin_axis, x - lever_origin)
        else:
            trial = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            t = trial
        t = t - (t @ n) * n
        norm = np.linalg.norm(t)
        t = t / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
        frames[i] = [n, t, np.cross(n, t)]
    return frames


def node_dofs(model, point: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """(node coordinates, global displacement DOF per axis or -1 if held) of the mesh node nearest ``point``
    (the same node on every rank)."""
    comm = model.comm
    W = model.W
    imap = W.dofmap.index_map
    n_owned = imap.size_local
    held = set(np.asarray(model.support_dofs).tolist())
    out, x_node = [], None
    for k in range(model.mesh.geometry.dim):
        V, parent = W.sub(0).sub(k).collapse()
        parent = np.asarray(parent)
        coords = V.tabulate_dof_coordinates()[:, : point.size]
        owned = parent < n_owned
        dist = np.linalg.norm(coords - point[: coords.shape[1]], axis=1)
        dist[~owned] = np.inf
        best = int(np.argmin(dist)) if dist.size else -1
        d = float(dist[best]) if best >= 0 else np.inf
        _, owner = comm.allreduce((d, comm.rank), op=MPI.MINLOC)
        if comm.rank == owner:
            local = int(parent[best])
            dof = -1 if local in held else int(imap.local_to_global(np.array([local], dtype=np.int32))[0])
            x = coords[best]
        else:
            dof, x = None, None
        out.append(comm.bcast(dof, root=owner))
        x_node = comm.bcast(x, root=owner)
    return np.asarray(x_node, dtype=float), out


def farthest_point_subset(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` indices of ``points`` spread over them (greedy farthest-point sampling from the first)."""
    chosen = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    while len(chosen) < count:
        nxt = int(np.argmax(distance))
        chosen.append(nxt)
        distance = np.minimum(distance, np.linalg.norm(points - points[nxt], axis=1))
    return np.array(sorted(chosen))


def contact_site_sets(case, model):
    """The site sets of the case's node and surface contacts (app/reduced/sites.py) and the interface: global
    DOFs in interface-coordinate order. Every check that needs the mesh (facet groups, node points, the
    interface size) raises the one-line CaseError here, so ``validate`` runs it without reducing."""
    from app.contact.surface import surface_nodes
    from app.fe.model import facet_group_tag
    from forms.kinematics import volume_weight

    file, cfg = case.source, case.transient
    gdim = model.mesh.geometry.dim
    weight = volume_weight(model.mesh, model.kind, case.geometry.thickness_m)
    bodies = {b.name: b for b in cfg.bodies}
    sets, areas = [], np.zeros(len(cfg.contacts))
    for i, c in enumerate(cfg.contacts):
        key = f"transient.contacts[{i}]"
        if c.kind == "node":
            if c.node_point not in case.points:
                raise CaseError(file, f"{key}.node_point", f"unknown point {c.node_point!r} (see [points])")
            normal = np.asarray(c.normal, dtype=float)
            if normal.size != gdim or not math.isclose(np.linalg.norm(normal), 1.0, rel_tol=1e-9):
                raise CaseError(file, f"{key}.normal", f"must be a unit vector with {gdim} components")
            x_node, dofs = node_dofs(model, np.asarray(case.points[c.node_point].coordinates_m, dtype=float))
            dofs = np.array(dofs, dtype=np.int64)
            if c.friction is None:      # frictionless: only the normal's components move the gap
                dofs = np.where(normal != 0.0, dofs, -1)
            if (dofs < 0).all():
                raise CaseError(file, f"{key}.node_point", "the node has no free displacement DOF along the normal")
            point = np.zeros(3)
            point[:gdim] = x_node
            sets.append(SiteSet(i, c.name, point.reshape(1, 3), np.ones(1), dofs.reshape(1, gdim),
                                dofs.reshape(1, gdim)))
            continue
        if c.kind != "surface":
            continue
        tag = facet_group_tag(model.mesh_data.facet_names, c.facets, file, f"{key}.facets")
        nodes = surface_nodes(model.W, model.W.sub(0), model.mesh_data.facet_tags, tag, weight, model.support_dofs)
        if nodes.size == 0:
            raise CaseError(file, f"{key}.facets", f"facet group {c.facets!r} has no nodes")
        areas[i] = float(nodes.area_m2.sum())
        if c.sampling == "ring":
            if case.reduction.interface == "band" and case.reduction.site_displacement != "interface":
                raise CaseError(file, "reduction.interface", '"band" needs reduction.site_displacement = "interface" '
                                                             "(the sites interpolated from the band's stations)")
            k = case.reduction.interface_nodes or min(64, nodes.size)
            sets.append(ring_sites(i, c, case, bodies[c.body], nodes, areas[i], c.sample_points, k,
                                   case.reduction.site_displacement, key, band=case.reduction.interface == "band",
                                   n_rings=c.sample_rings))
            continue
        points = np.zeros((nodes.size, 3))
        points[:, :gdim] = nodes.coordinates_m
        k = case.reduction.interface_nodes
        if k is not None and k > nodes.size:
            raise CaseError(file, "reduction.interface_nodes", f"the facet group of {key} has only {nodes.size} nodes")
        chosen = np.arange(nodes.size) if k is None else farthest_point_subset(points, k)
        sets.append(SiteSet(i, c.name, points, nodes.area_m2, nodes.global_dofs[chosen], nodes.global_dofs))
    if case.reduction.interface == "band" and not any(s.ring is not None for s in sets):
        raise CaseError(file, "reduction.interface", '"band" needs a surface contact with sampling = "ring"')
    interface: list[int] = []
    seen = set()
    for s in sets:
        for row in s.interface_dofs:
            for d in row:
                if d >= 0 and int(d) not in seen:
                    seen.add(int(d))
                    interface.append(int(d))
    return sets, np.array(interface, dtype=np.int64), areas
