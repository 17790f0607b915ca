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


def ring_sites(contact_index: int, section, case, body, nodes, area_m2: float, n_points: int, n_interface: int,
               rule: str, prefix: str, band: bool = False) -> SiteSet:
    """Ring sampling of a surface contact (module docstring): ``nodes`` are the facet group's nodes
    (app/reduced/surface.py SurfaceNodes), ``area_m2`` its area. ``band``: the band interface
    (:func:`ring_band_patterns`): ``n_interface`` stations on each edge of the band (its lowest and highest
    nodes along the axis), the band and the sites interpolated cubically in angle and linearly in height."""
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
    site_angles = 2 * math.pi * (np.arange(n_points) + 0.5) / n_points
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
    points = centre + h_c * axis + radius * (np.outer(np.cos(site_angles), e1) + np.outer(np.sin(site_angles), e2))
    ring = {"axis": axis, "centre": centre, "e1": e1, "e2": e2, "node_angles": angles_nodes[chosen],
            "site_angles": site_angles, "rule": rule,
            # stations: ``levels`` rings of k interface nodes (level-major), each point's weight per level
            "levels": heights.size, "site_level_weights": level_weights(np.full(n_points, h_c)),
            # every node of the band, for the band interface (ring_band_patterns)
            "band_angles": angles_nodes, "band_dofs": nodes.global_dofs, "band_xyz": xyz,
            "band_level_weights": level_weights(height)}
    return SiteSet(contact_index, section.name, points, np.full(n_points, area_m2 / n_points),
                   nodes.global_dofs[chosen], None, ring)


def ring_interface_rows(ring: dict, n_interface_before: int, gdim: int, n_columns: int) -> np.ndarray:
    """Rows (n_sites * 3, n_columns) of the ring's sites interpolated from its interface nodes (whose
    coordinates start at ``n_interface_before``, gdim per node in component order): cubic Lagrange in angle of
    the cylindrical components, within each level of stations (one; two for the band interface, then linear in
    height between them)."""
    site_angles, axis = ring["site_angles"], ring["axis"]
    levels = ring.get("levels", 1)
    per_level = ring["node_angles"].size // levels
    site_frames = cylindrical_frames(site_angles, ring["e1"], ring["e2"], axis)
    rows = np.zeros((site_angles.size * 3, n_columns))
    for level in range(levels):
        node_angles = ring["node_angles"][level * per_level:(level + 1) * per_level]
        idx, weights = interpolation_stencil(node_angles, site_angles)
        if levels > 1:
            weights = weights * ring["site_level_weights"][:, level:level + 1]
        node_frames = cylindrical_frames(node_angles, ring["e1"], ring["e2"], axis)
        first = n_interface_before + gdim * level * per_level
        for c in range(site_angles.size):
            for s in range(idx.shape[1]):
                j = idx[c, s]
                # global at the site = F_c^T (local at the site) = F_c^T w F_j (global at node j)
                block = weights[c, s] * site_frames[c].T @ node_frames[j]
                for r in range(3):
                    for kk in range(gdim):
                        rows[3 * c + r, first + gdim * j + kk] += block[r, kk]
    return rows


def ring_band_patterns(ring: dict, interface_dofs: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """The band interface (``reduction.interface = "band"``): each interface coordinate of a ring, interface node k's
    global component c (its DOF ``interface_dofs[k, c]``), as a displacement pattern of every node of the contact
    band: node j moves by w_jk F_j^T F_k e_c, the same periodic cubic Lagrange interpolation in angle of the
    cylindrical components as the sites' rows (:func:`ring_interface_rows`). Returns {interface DOF: (global DOFs,
    values)}; held DOFs (-1) are left out. At an interface node the pattern is the unit displacement of that DOF
    (Lagrange weights), so the coordinate is still the node's displacement; between them the band follows the
    interpolation instead of being free, so the sites' forces act on the band as loads spread over it rather than
    as point loads on a few nodes, whose local compliance does not converge (3D: it grows like 1/h)."""
    band_angles, band_dofs = ring["band_angles"], ring["band_dofs"]
    levels = ring.get("levels", 1)
    per_level = ring["node_angles"].size // levels
    band_frames = cylindrical_frames(band_angles, ring["e1"], ring["e2"], ring["axis"])
    gdim = band_dofs.shape[1]
    collected: dict[int, tuple[list, list]] = {}
    for level in range(levels):
        station_angles = ring["node_angles"][level * per_level:(level + 1) * per_level]
        idx, weights = interpolation_stencil(station_angles, band_angles)
        weights = weights * ring["band_level_weights"][:, level:level + 1]
        station_frames = cylindrical_frames(station_angles, ring["e1"], ring["e2"], ring["axis"])
        for j in range(band_angles.size):
            for s in range(idx.shape[1]):
                if weights[j, s] == 0.0:
                    continue
                k = level * per_level + idx[j, s]
                # global at band node j = F_j^T w F_k (global at station k)
                block = weights[j, s] * band_frames[j].T @ station_frames[idx[j, s]]
                for c in range(gdim):
                    key = int(interface_dofs[k, c])
                    if key < 0:
                        continue
                    dofs, values = collected.setdefault(key, ([], []))
                    for r in range(gdim):
                        if band_dofs[j, r] >= 0 and block[r, c] != 0.0:
                            dofs.append(int(band_dofs[j, r]))
                            values.append(float(block[r, c]))
    out = {}
    for key, (dofs, values) in collected.items():
        dofs_arr, values_arr = np.asarray(dofs, dtype=np.int64), np.asarray(values)
        unique, inverse = np.unique(dofs_arr, return_inverse=True)
        out[key] = (unique, np.bincount(inverse, weights=values_arr, minlength=unique.size))
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
                                   case.reduction.site_displacement, key, band=case.reduction.interface == "band"))
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
