"""Synthetic scenes for the modal tier's compiled loop (app/reduced/kernel.py), built directly as its records:
a reduced structure (K, M, C and site rows), rigid bodies, sites with their contacts, links. The tests use it
to check the kernel against closed forms and the FE tier without a case file."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from app.contact import law
from app.reduced import kernel as kr

SHAPES = {"plane": law.PLANE, "sphere": law.SPHERE, "cone": law.CONE}


@dataclasses.dataclass
class Body:
    mass_kg: float
    position_m: list
    free: list                                  # per translation (and rotation) coordinate
    load_N: list | None = None                  # generalized load per coordinate
    velocity: list | None = None                # initial rates per coordinate
    rotations: list = dataclasses.field(default_factory=list)       # axis vectors (3,)
    inertia: list = dataclasses.field(default_factory=list)
    brake: list = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class Contact:
    body: int
    kind: int = law.SURFACE
    shape: str = "plane"
    vector: tuple = (0.0, 0.0, 0.0)
    radius_m: float = 0.0
    half_angle_rad: float = 0.0
    stiffness: float = 1e13
    damping: float = 0.0
    rounding_m: float = 0.0
    exponent: float = 1.0
    friction: tuple = (0.0, 1.0, 0.0, 1e20, 1e-4)     # mu_d, FACT, DC, cap, eps


@dataclasses.dataclass
class Link:
    lower: int
    upper: int
    direction: tuple
    touch_m: float
    stiffness: float
    damping: float = 0.0
    offset_m: float = 0.0
    friction: tuple = (0.0, 1.0, 0.0, 1e20, 1e-4)


def bodies_record(bodies: list[Body], gdim: int) -> law.Bodies:
    start, mass, free, load, brake, axis, rate = [], [], [], [], [], [], []
    reference = np.zeros((max(len(bodies), 1), 3))
    m = 0
    for i, b in enumerate(bodies):
        start.append(m)
        reference[i, :gdim] = b.position_m
        n = gdim + len(b.rotations)
        mass += [b.mass_kg] * gdim + list(b.inertia)
        free += list(b.free)
        load += list(b.load_N or [0.0] * n)
        brake += [0.0] * gdim + list(b.brake or [0.0] * len(b.rotations))
        axis += [(0.0, 0.0, 0.0)] * gdim + [tuple(a) for a in b.rotations]
        rate += [0.0] * n
        m += n
    return law.Bodies(gdim, np.array(start, np.int64), np.array(mass, float), np.array(free, np.bool_),
                      np.array(load, float), np.array(brake, float), np.array(axis, float).reshape(m, 3),
                      np.array(rate, float), reference)


def contacts_record(contacts: list[Contact]) -> law.Contacts:
    rows = [(c.kind, SHAPES[c.shape], c.body, np.asarray(c.vector, float), c.radius_m, c.half_angle_rad, c.stiffness,
             c.damping, c.rounding_m, c.exponent, *c.friction) for c in contacts]
    cols = list(zip(*rows)) if rows else [[]] * 15
    return law.Contacts(np.array(cols[0], np.int64), np.array(cols[1], np.int64), np.array(cols[2], np.int64),
                        np.array(cols[3], float).reshape(-1, 3), *(np.array(cols[k], float) for k in range(4, 15)))


def links_record(links: list[Link]) -> law.Links:
    rows = [(k.lower, k.upper, np.asarray(k.direction, float), k.touch_m, k.stiffness, k.damping, k.offset_m,
             *k.friction) for k in links]
    cols = list(zip(*rows)) if rows else [[]] * 12
    return law.Links(np.array(cols[0], np.int64), np.array(cols[1], np.int64), np.array(cols[2], float).reshape(-1, 3),
                     *(np.array(cols[k], float) for k in range(3, 12)))


def sites_record(points, weight, contact, rows, contacts: law.Contacts, bodies: law.Bodies, exclude=False,
                 frame=None) -> law.Sites:
    """Sites at ``points`` (n, 3) of the given contacts; ``rows`` (n * gdim, n_q)."""
    points = np.asarray(points, float)
    n = points.shape[0]
    rel, lever, gap_ref = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
    normal, Dn = np.zeros(3), np.zeros((3, 3))
    for i in range(n):
        c = contact[i]
        ref = bodies.reference[contacts.body[c]]
        lever[i] = points[i] - ref
        rel[i] = points[i] - ref
        if contacts.shape[c] == law.SPHERE and np.any(contacts.vector[c]) and contacts.kind[c] == law.SURFACE:
            rel[i] -= contacts.radius[c] * contacts.vector[c]
        if exclude:
            gap_ref[i] = law.shape_gap(contacts.shape[c], contacts.vector[c], contacts.radius[c],
                                       contacts.half_angle[c], rel[i].copy(), normal, Dn)
    if frame is None:
        frame = np.tile(np.eye(3), (n, 1, 1))
    return law.Sites(np.asarray(rows, float), rel, lever, gap_ref, np.asarray(weight, float),
                     np.asarray(contact, np.int64), np.asarray(frame, float))


def run(K, M, C, q, v, a, bodies: list[Body], gdim: int, sites: law.Sites | None, contacts: list[Contact],
        links: list[Link], scheme, sizes, t_end: float, cap: int = 400000, load=None, final: list | None = None):
    """Step the scene to ``t_end``: (records as the FE tier's run_scene gives them, istate); ``final`` (a list) gets
    the loop's final state."""
    n = K.shape[0]
    B = bodies_record(bodies, gdim)
    Cr = contacts_record(contacts)
    L = links_record(links)
    if sites is None:
        sites = sites_record(np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64), np.zeros((0, n)), Cr, B)
    m = B.mass.size
    z = np.concatenate([np.concatenate([b.position_m, np.zeros(len(b.rotations))]) for b in bodies])
    zd = np.concatenate([np.asarray(b.velocity or [0.0] * (gdim + len(b.rotations)), float) for b in bodies])
    zdd = np.zeros(m)
    loaded = B.free & (B.mass > 0)
    zdd[loaded] = B.load[loaded] / B.mass[loaded]
    structure = kr.Structure(K, M, C, np.zeros(n) if load is None else load, np.arange(n, dtype=np.int64),
                             np.zeros(0, np.int64))
    inputs = kr.Inputs(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), 1.0, False)
    control = kr.Control(sizes.open_s, sizes.closed_s, sizes.change_s, sizes.min_s, 2.0)
    n_c, n_l = Cr.kind.size, L.lower.size
    out = kr.Outputs(np.zeros(cap), np.zeros(cap), np.zeros((cap, 0)), np.zeros((cap, 0)), np.zeros((cap, m)),
                     np.zeros((cap, m)), np.zeros((cap, n_c + n_l, 3)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c)),
                     np.zeros((cap, n_c)), np.zeros((cap, n_c + n_l), np.bool_), np.zeros((cap, n_c + n_l)),
                     np.zeros((cap, 5)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c)),
                     np.zeros((sites.contact.size, 14)), np.zeros((1, 36, 8)),
                     np.zeros(sites.contact.size, np.int64), np.full(sites.contact.size, np.nan))
    sums = kr.Sums(np.zeros(n_c + n_l), np.full(n_c + n_l, np.nan), np.zeros(2))
    istate = np.zeros(kr.N_ISTATE, np.int64)
    fstate = np.zeros(kr.N_FSTATE)
    fstate[kr.F_CAP] = np.inf
    fstate[kr.F_STOP] = np.inf
    cache = kr.make_cache(n, sites.rows.shape[0])
    state = kr.State(np.array(q, float), np.array(v, float), np.array(a, float), z, zd, zdd, istate, fstate, sums,
                     np.zeros((sites.contact.size, 3)))
    model = kr.Model(structure, inputs, kr.Scheme(scheme.beta, scheme.gamma, scheme.alpha_m, scheme.alpha_f), control,
                     B, sites, Cr, L, np.zeros((0, n)))
    code, rows = kr.run(t_end, state, model, cache, out, False, kr.no_frames(n, z.size))
    assert code == kr.DONE, code
    records = []
    for i in range(rows):
        records.append({"time_s": out.time[i], "position_m": out.z[i].copy(), "velocity_m_per_s": out.zd[i].copy(),
                        "contact_force_N": {f"c{c}": out.force[i, c, :gdim].copy() for c in range(n_c + n_l)},
                        "contact_closed": out.closed[i].astype(int),
                        "dissipated_J": {f"c{c}": float(out.dissipated[i, c]) for c in range(n_c + n_l)}})
    if final is not None:
        final.append(state)
    return records, istate


def hertz_duration_s(mass_kg: float, k: float, v0: float, exponent: float = 1.5) -> float:
    """Duration of a power-law (F = k d^e) impact of a mass against a rigid wall at speed v0 (closed form)."""
    d_max = ((exponent + 1) * mass_kg * v0**2 / (2 * k)) ** (1 / (exponent + 1))
    integral = math.sqrt(math.pi) * math.gamma(1 + 1 / (exponent + 1)) / math.gamma(0.5 + 1 / (exponent + 1))
    return 2 * d_max / v0 * integral
