"""The contact law's records (app/contact/law.py) built from a case: the rigid bodies, the contacts that act
through sites (surface, node) and the rigid-rigid links, and the sites of a sampling (app/contact/sites.py), in
the order every tier uses (the case's, node and surface contacts first among the sites' contacts)."""

from __future__ import annotations

import math

import numpy as np

from app.contact import law as lk
from app.errors import CaseError

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0), "plane": (0.0, 0.0, 1.0)}
SHAPES = {"plane": lk.PLANE, "sphere": lk.SPHERE, "cone": lk.CONE}


def site_contacts(case) -> list:
    """The case's contacts that act through sites (node and surface), in case order."""
    return [c for c in case.transient.contacts if c.kind != "point"]


def bodies_record(case, gdim: int, gravity: np.ndarray):
    """(Bodies record, slice of each body's coordinates by name)."""
    cfg = case.transient
    start, mass, free, load, brake, axis, rate = [], [], [], [], [], [], []
    reference = np.zeros((max(len(cfg.bodies), 1), 3))
    slices = {}
    m = 0
    for i, b in enumerate(cfg.bodies):
        if len(b.position_m) != gdim:
            raise CaseError(case.source, f"transient.bodies[{i}].position_m", f"needs {gdim} coordinates")
        start.append(m)
        reference[i, :gdim] = b.position_m
        velocity = list(b.velocity_m_per_s or [0.0] * gdim)
        free_axes = [False] * gdim if b.fixed else list(b.free_axes or [True] * gdim)
        force = np.asarray(b.applied_force_N or [0.0] * gdim, dtype=float)
        g = np.zeros(gdim) if b.fixed else gravity
        for k in range(gdim):
            mass.append(b.mass_kg)
            free.append(free_axes[k])
            load.append(b.mass_kg * g[k] + force[k])
            brake.append(0.0)
            axis.append((0.0, 0.0, 0.0))
            rate.append(0.0 if b.fixed or free_axes[k] else velocity[k])
        for r in b.rotations:
            mass.append(r.inertia_kg_m2)
            free.append(r.motion == "free")
            load.append(r.torque_N_m if r.motion == "free" else 0.0)
            brake.append(r.brake_N_m_s_per_rad if r.motion == "free" else 0.0)
            axis.append(AXES[r.axis])
            rate.append(r.rate_rad_per_s if r.motion == "constant_rate" else 0.0)
        slices[b.name] = slice(m, m + gdim + len(b.rotations))
        m += gdim + len(b.rotations)
    record = lk.Bodies(gdim, np.array(start, np.int64), np.array(mass, float), np.array(free, np.bool_),
                       np.array(load, float), np.array(brake, float), np.array(axis, float).reshape(m, 3),
                       np.array(rate, float), reference)
    return record, slices


def contact_records(case):
    """(Contacts record of the node and surface contacts, Links record of the point contacts)."""
    cfg = case.transient
    index = {b.name: i for i, b in enumerate(cfg.bodies)}
    rows = []
    for c in cfg.contacts:
        if c.kind == "point":
            continue
        f = c.friction
        friction = (f.mu_dynamic, f.static_ratio, f.decay_s_per_m,
                    f.shear_cap_Pa if c.kind == "surface" else f.force_cap_N,
                    f.regularisation_speed_m_per_s) if f is not None else (0.0, 1.0, 0.0, 1e20, 1e-4)
        vector = np.zeros(3)
        if c.kind == "node":
            vector[:len(c.normal)] = c.normal
            rows.append((lk.NODE, lk.SPHERE, index[c.body], vector, c.radius_m, 0.0, c.stiffness, c.damping, 0.0,
                         1.5, *friction))
            continue
        if c.shape == "cone":
            vector[:] = c.axis
        elif c.normal is not None:
            vector[:len(c.normal)] = c.normal
        rows.append((lk.SURFACE, SHAPES[c.shape], index[c.body], vector, c.radius_m or 0.0,
                     math.radians(c.half_angle_deg or 0.0), c.stiffness, c.damping, c.rounding_m, 1.0, *friction))
    cols = list(zip(*rows)) if rows else [[]] * 15
    contacts = lk.Contacts(np.array(cols[0], np.int64), np.array(cols[1], np.int64), np.array(cols[2], np.int64),
                           np.array(cols[3], float).reshape(-1, 3), *(np.array(cols[k], float) for k in range(4, 15)))
    links = []
    for c in cfg.contacts:
        if c.kind != "point":
            continue
        f = c.friction
        friction = (f.mu_dynamic, f.static_ratio, f.decay_s_per_m, f.force_cap_N, f.regularisation_speed_m_per_s) \
            if f is not None else (0.0, 1.0, 0.0, 1e20, 1e-4)
        direction = np.zeros(3)
        direction[:len(c.direction)] = np.asarray(c.direction, float) / np.linalg.norm(c.direction)
        links.append((index[c.lower], index[c.upper], direction, c.touch_distance_m, c.stiffness, c.damping,
                      c.contact_offset_m, *friction))
    cols = list(zip(*links)) if links else [[]] * 12
    links = lk.Links(np.array(cols[0], np.int64), np.array(cols[1], np.int64), np.array(cols[2], float).reshape(-1, 3),
                     *(np.array(cols[k], float) for k in range(3, 12)))
    return contacts, links


def sites_record(case, points, weight, contact_index, rows, contacts, bodies):
    """Sites in the law's terms: reference geometry relative to their body and obstacle, excluded initial
    gaps, diagnostics frames. ``points`` (n, 3), ``weight`` (n,), ``contact_index``: the case's contact index
    of each site, ``rows``: their displacement rows (the modal tier's; the FE tier: zeros)."""
    from app.contact.sites import site_frames

    cfg = case.transient
    kernel_index = {}            # case contact index -> kernel contact index (node and surface contacts)
    k = 0
    for i, c in enumerate(cfg.contacts):
        if c.kind != "point":
            kernel_index[i] = k
            k += 1
    site_contact = np.array([kernel_index[int(c)] for c in contact_index], np.int64)
    ns = site_contact.size
    rel = np.zeros((ns, 3))
    lever = np.zeros((ns, 3))
    gap_ref = np.zeros(ns)
    normals = np.zeros((ns, 3))
    n = np.zeros(3)
    Dn = np.zeros((3, 3))
    for i in range(ns):
        c = site_contact[i]
        b = contacts.body[c]
        ref = bodies.reference[b]
        x = points[i]
        lever[i] = x - ref
        rel[i] = x - ref
        if contacts.kind[c] == lk.SURFACE and contacts.shape[c] == lk.SPHERE and np.any(contacts.vector[c]):
            rel[i] = x - (ref + contacts.radius[c] * contacts.vector[c])
        if contacts.kind[c] == lk.NODE:
            normals[i] = contacts.vector[c]
            continue
        gap = lk.shape_gap(contacts.shape[c], contacts.vector[c], contacts.radius[c], contacts.half_angle[c],
                           rel[i].copy(), n, Dn)
        normals[i] = n
        case_index = next(j for j, kk in kernel_index.items() if kk == c)
        if cfg.contacts[case_index].exclude_initial_gap:
            gap_ref[i] = gap
    frames = np.zeros((ns, 3, 3))
    for i in range(ns):
        c = site_contact[i]
        b = contacts.body[c]
        body = cfg.bodies[b]
        spin = np.array(AXES[body.rotations[0].axis]) if body.rotations else None
        frames[i] = site_frames(points[i:i + 1], normals[i:i + 1], spin, bodies.reference[b])[0]
    return lk.Sites(rows, rel, lever, gap_ref, weight, site_contact, frames)


