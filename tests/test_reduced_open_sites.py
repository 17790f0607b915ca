"""The modal kernel evaluates the contact law only on the sites that can touch (issue 27, app/reduced/kernel.py
_surely_open): a site whose relative position d stays within a distance of the last d the law saw it at, over
which its gap cannot fall to zero (the gap's Lipschitz constant in d, :func:`_gap_lipschitz`), is open without
the law. Exactness is the requirement: the condensed step, its Newton system and the per-site diagnostics must be
those of the law evaluated at every site, to the bit.

* The Lipschitz constants against the shapes' gaps (app/contact/law.py shape_gap; the node gap n.d): the triangle
  inequality |g(d) - g(d')| <= L |d - d'| on random pairs, and the constant attained (a move along the normal).
* A ring of sites on the motor's cone, a spinning rotor: a sequence of Newton iterates (small moves that leave most
  sites skipped, then the rotor pressed down, then skipped sites pushed through the cone face one by one) evaluated
  with the bound carried from iterate to iterate and by the law at every site (a fresh work record, the path before
  the bound): the same active sites, forces, slips, lever arms, residuals and derivatives, bit for bit; then the
  per-site diagnostics of an accepted step (_record) from both, bit for bit.
"""

import math

import numpy as np
import pytest
from reduced_scene import Body, Contact, bodies_record, contacts_record, links_record, sites_record

from app.contact import law
from app.reduced import kernel as kr

SHAPES = {
    # contact kind, shape, vector, radius, half angle, a point relative to the body's reference
    "plane": (law.SURFACE, "plane", (0.0, 0.6, 0.8), 0.0, 0.0, (3e-3, -2e-3, 1e-6)),
    "sphere": (law.SURFACE, "sphere", (0.0, 0.0, 0.0), 4e-3, 0.0, (1e-3, 0.5e-3, 3.9e-3)),
    "sphere-pole": (law.SURFACE, "sphere", (0.0, 0.0, 1.0), 4e-3, 0.0, (1e-3, 0.5e-3, 3.9e-3)),
    "cone": (law.SURFACE, "cone", (0.0, 0.0, 1.0), 0.0128, math.radians(15.0), (0.0128, 0.0, 0.0)),
    "node": (law.NODE, "sphere", (0.0, 0.0, 2.0), 4e-3, 0.0, (0.0, 0.0, 2e-3)),
}


@pytest.mark.parametrize("key", list(SHAPES))
def test_gap_lipschitz_constant_bounds_every_shape(key):
    """|g(d) - g(d')| <= L |d - d'| for the constant the kernel skips sites by, on 2000 random pairs 1 nm to 0.1 mm
    apart near the site (the reference: the triangle inequality, which the closed forms satisfy exactly; the
    computed gaps differ from it by their rounding, ~1e-18 m, far below the 1e-9 L |d - d'| >= 1e-18 m slack the
    kernel's L carries). And L is no looser than it needs be: a move along the obstacle's normal changes the gap
    by L |d - d'| to 1e-6 (the constants are exact: 1, or |n| for a plane's and a node's n.d), so a bound taken
    too small (cos a for the cone, 1 for a node's |n| = 2) fails the first check and one taken too large the
    second."""
    kind, shape, vector, radius, half, point = SHAPES[key]
    body = Body(0.018, [0.0, 0.0, 0.0], [True, True, True])
    B = bodies_record([body], 3)
    C = contacts_record([Contact(0, kind, shape, vector, radius, half)])
    S = sites_record([point], [4e-7], [0], np.zeros((3, 0)), C, B)
    lipschitz = kr._gap_lipschitz(C, 0)
    work = law.site_work(B.mass.size)
    zero = np.zeros(B.mass.size)

    def gap(y):
        out = law.site_force(0, y, np.zeros(3), zero, zero, S, C, B, 1.0, 1.0, False, work)[1]
        return out, work.n.copy()

    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(2000):
        y = rng.normal(size=3) * 1e-5
        step = rng.normal(size=3)
        step *= 10.0 ** rng.uniform(-9, -4) / np.linalg.norm(step)
        g0, _ = gap(y)
        g1, _ = gap(y + step)
        worst = max(worst, abs(g1 - g0) / np.linalg.norm(step))
    assert worst <= lipschitz
    y = rng.normal(size=3) * 1e-6
    g0, normal = gap(y)
    h = 1e-8
    g1, _ = gap(y + h * normal / np.linalg.norm(normal))
    assert abs(g1 - g0) / h == pytest.approx(lipschitz, rel=1e-6)


def _ring_scene(n_sites=48):
    """The motor's cone (radius 12.8 mm, 15 deg) and a spinning rotor free axially and in spin, ``n_sites`` sites
    round the ring with the reference gap excluded, friction in slip; a random SPD compliance H (1e-9 m/N)."""
    rng = np.random.default_rng(17)
    gdim = 3
    alpha = math.radians(15.0)
    rotor = Body(0.018, [0.0, 0.0, 0.0], [False, False, True, True], load_N=[0.0, 0.0, -0.98, -0.004],
                 rotations=[(0.0, 0.0, 1.0)], inertia=[1.52e-6], brake=[1e-4])
    contact = Contact(0, law.SURFACE, "cone", (0.0, 0.0, 1.0), 0.0128, alpha, stiffness=4e13, damping=3e5,
                      rounding_m=1e-9, friction=(0.57, 1.298, 50.0, 124.13e6, 1e-4))
    B, C, L = bodies_record([rotor], gdim), contacts_record([contact]), links_record([])
    angles = 2 * math.pi * np.arange(n_sites) / n_sites
    points = np.column_stack([0.0128 * np.cos(angles), 0.0128 * np.sin(angles), np.zeros(n_sites)])
    S = sites_record(points, np.full(n_sites, 4e-7), np.zeros(n_sites, np.int64), np.zeros((n_sites * gdim, 0)),
                     C, B, exclude=True)
    normals = np.column_stack([math.cos(alpha) * np.cos(angles), math.cos(alpha) * np.sin(angles),
                               np.full(n_sites, -math.sin(alpha))])
    nr = n_sites * gdim
    A = rng.normal(size=(nr, nr))
    H = 1e-9 * (A @ A.T / nr + np.eye(nr))
    dt = 6.93e-7
    m = B.mass.size
    state = kr.State(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(m), np.array([0.0, 0.0, 1e-4, 3.0]),
                     np.array([0.0, 0.0, -50.0, 0.0]), np.zeros(kr.N_ISTATE, np.int64), np.zeros(kr.N_FSTATE),
                     kr.Sums(np.zeros(1), np.full(1, np.nan), np.zeros(2)), np.zeros((n_sites, 3)))
    empty = np.zeros((0, 0))
    model = kr.Model(kr.Structure(empty, empty, empty, np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)),
                     kr.Inputs(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), 2e5, False),
                     kr.Scheme(0.25, 0.5, 0.0, 0.0), kr.Control(dt, dt, dt, 1e-14, 2.0), B, S, C, L,
                     np.zeros((0, 0)))
    # gaps from 30 nm inside (every 8th site) to 2 um open, log-spaced
    depth = np.geomspace(1e-9, 2e-6, n_sites)
    depth[::8] = -3e-8
    rng.shuffle(depth)

    def work():
        wk = kr.step_work(n_sites, gdim, m, 4, 0)
        wk.y0[:] = depth[:, None] * normals
        wk.v0[:] = np.random.default_rng(2).normal(size=(n_sites, 3)) * 1e-3
        wk.a0[:] = np.random.default_rng(3).normal(size=(n_sites, 3)) * 10.0
        wk.dw[:] = np.random.default_rng(4).normal(size=nr) * 1e-10
        return wk

    return model, state, kr.dense_compliance(H), work, normals, dt


def _evaluations_agree(bounded, law_everywhere, n_bounded, n_law):
    """The fields of two evaluations the step reads, bit for bit; returns the sites the bound skipped."""
    assert n_bounded == n_law
    np.testing.assert_array_equal(bounded.active[:n_law], law_everywhere.active[:n_law])
    for name in ("fn", "f", "slip", "lever", "R", "rz", "Q", "dQ", "Hf", "z_mid", "zd_mid", "z1", "zd1", "zdd1"):
        np.testing.assert_array_equal(getattr(bounded, name), getattr(law_everywhere, name), err_msg=name)
    active = law_everywhere.active[:n_law]
    np.testing.assert_array_equal(bounded.Fd[active], law_everywhere.Fd[active])
    np.testing.assert_array_equal(bounded.Fz[active], law_everywhere.Fz[active])
    # a closed site is always evaluated (its exact gap); a skipped one carries a positive lower bound of its gap
    closed = law_everywhere.gap <= 0.0
    np.testing.assert_array_equal(bounded.gap[closed], law_everywhere.gap[closed])
    skipped = bounded.gap != law_everywhere.gap
    assert np.all(bounded.gap[skipped] > 0.0)
    assert np.all(bounded.gap[skipped] <= law_everywhere.gap[skipped])
    return np.flatnonzero(skipped)


def test_sites_skipped_by_the_bound_are_those_the_law_finds_open():
    """Iterates of one step evaluated with the bound carried between them and by the law at every site (a fresh
    work record each time: the kernel before the bound). Exactness is the point, so the comparison is bitwise.
    The sequence is built to cross the bound: small moves (most open sites skipped: checked), then the rotor
    pressed 100 nm down (the sites within 26 nm of the face close through the body's coordinate alone, not their
    own increments), then each of five skipped sites pushed through the cone face along its normal by 1.01 x its
    gap. A bound that ignored the body's motion, or let a site move farther than its gap allows (twice, say), would
    skip a site the law finds pressed and fail here."""
    model, state, compliance, work, normals, dt = _ring_scene()
    n_sites = normals.shape[0]
    bounded = work()
    rng = np.random.default_rng(9)
    dd = bounded.dw + rng.normal(size=bounded.dw.size) * 1e-10
    xi = np.zeros(state.z.size)

    def both(dd, xi):
        fresh = work()
        n_b = kr._evaluate(dd, xi, bounded, compliance, state, dt, model, True)
        n_f = kr._evaluate(dd, xi, fresh, compliance, state, dt, model, True)
        return _evaluations_agree(bounded, fresh, n_b, n_f), fresh

    skipped, fresh = both(dd, xi)
    assert skipped.size == 0                      # the first evaluation of a work record: the law everywhere
    closed_at_start = int(np.sum(fresh.fn > 0.0))
    assert 0 < closed_at_start < n_sites
    for _ in range(3):                            # small moves: the open sites far from the face are skipped
        dd = dd + rng.normal(size=dd.size) * 1e-10
        skipped, fresh = both(dd, xi)
        assert skipped.size >= n_sites // 2
    # the rotor pressed down: sites close by the body's coordinate, their own increments unchanged
    xi[2] = -1e-7
    was_skipped = set(skipped.tolist())
    skipped, fresh = both(dd, xi)
    newly_closed = [i for i in np.flatnonzero(fresh.fn > 0.0) if i in was_skipped]
    assert len(newly_closed) >= 3
    # skipped sites pushed through the face one by one, along their normal, 1.01 x their gap
    pushed = 0
    for _ in range(5):
        skipped, fresh = both(dd, xi)
        i = skipped[np.argmin(fresh.gap[skipped])]
        dd = dd.copy()
        dd[3 * i:3 * i + 3] -= 1.01 * fresh.gap[i] * normals[i]
        _, fresh = both(dd, xi)
        assert fresh.gap[i] < 0.0 and fresh.fn[i] > 0.0
        pushed += 1
    assert pushed == 5

    # the per-site diagnostics and the output row of an accepted step at the last iterate, from either evaluation
    def record(wk):
        n_c, cap = 1, 2
        sums = kr.Sums(np.zeros(1), np.full(1, np.nan), np.zeros(2))
        st = state._replace(sums=sums)
        out = kr.Outputs(np.zeros(cap), np.zeros(cap), np.zeros((cap, 0)), np.zeros((cap, 0)),
                         np.zeros((cap, 4)), np.zeros((cap, 4)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c, 3)),
                         np.zeros((cap, n_c)), np.zeros((cap, n_c)), np.zeros((cap, n_c), np.bool_),
                         np.zeros((cap, n_c)), np.zeros((cap, 5)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c)),
                         np.zeros((n_sites, 14)), np.zeros((1, 36, 8)), np.zeros(n_sites, np.int64),
                         np.linspace(0.0, 6.0, n_sites))
        y_end = wk.y0 + dd.reshape(-1, 3)
        kr._record(0, dt, dt, np.zeros(0), np.zeros(0), wk, st, model, out, np.ones(n_c, np.bool_), y_end,
                   np.zeros(n_c), np.zeros(n_c, np.bool_), np.zeros(2))
        return out, sums

    (out_b, sums_b), (out_f, sums_f) = record(bounded), record(fresh)
    assert np.count_nonzero(out_f.site_sums[:, 0]) == int(np.sum(fresh.fn > 0.0))
    for name, a, b in zip(kr.Outputs._fields, out_b, out_f):
        np.testing.assert_array_equal(a, b, err_msg=name)
    for a, b in zip(sums_b, sums_f):
        np.testing.assert_array_equal(a, b)
