"""The modal kernel's products through K_eff^-1 (app/reduced/kernel.py, issue 27: "modal tier at its floor") against
the same products by G^T's rows, formed here with numpy from their definitions.

With many active sites whose rows R_F touch few coordinates S (a collapsed rotor: 1 536 active rows on 192
coordinates), G x = K_eff^-1 (R_F^T x), the Woodbury matrix I - R_A^T D G_A^T = I - (R_A^T D R_A) K_eff^-T and the
solve's G_A^T[:, S] sol = R_A (K_eff^-T[S, S] sol) cost nnz + |S| x nf, nnz(B) x |S| and |S|^2 + nnz instead of a
dense row of G^T per active row. The kernel takes the cheaper way per call; here each way is called by name and the
choosing one is checked to take the expected way.

Reference: G^T = R_F K_eff^-T (the kernel's definition, app/reduced/kernel.py _effective: G = K_eff^-1 R_F^T) and the
Woodbury system of _woodbury's docstring, formed densely with numpy. Tolerance 1e-12 relative: both sides are sums of
a few tens of products of O(1) numbers in different orders (round-off ~1e-15 relative; the matrices are well
conditioned, the LU solves at condition ~10 lose one digit); a transposed K_eff^-1 on the non-symmetric case, a
dropped scatter entry or a missing site block is an O(1) error.
"""

import math

import numpy as np
import pytest
from reduced_scene import Body, Contact, bodies_record, contacts_record, links_record, sites_record

from app.contact import law
from app.reduced import kernel as kr

RTOL = 1e-12


def _site_rows(rng, n_sites, nf, ring):
    """Site rows as the motor's interface sites have them (bench: 512 sites, rows of 4 and 8 entries, the three rows
    of a site on different supports): site i on 4 consecutive coordinates of a ring of ``ring`` (< nf: some free
    coordinates untouched), its first row on 2 of them, the other two on all 4."""
    RF = np.zeros((3 * n_sites, nf))
    start = rng.permutation(ring)
    for i in range(n_sites):
        support = [(start[i % ring] + j) % ring for j in range(4)]
        RF[3 * i, support[:2]] = rng.normal(size=2)
        RF[3 * i + 1:3 * i + 3, support] = rng.normal(size=(2, 4))
    return RF


def _inverse(rng, nf, symmetric):
    """K_eff^-1 of a symmetric positive-definite K_eff, or (``symmetric`` False) of K_eff plus a skew part of the same
    order, so a transposed K_eff^-1 is an O(1) error."""
    A = rng.normal(size=(nf, nf))
    K = A @ A.T / nf + np.eye(nf)
    if not symmetric:
        skew = rng.normal(size=(nf, nf))
        K = K + 0.5 * (skew - skew.T)
    return np.linalg.inv(K)


def _scene(n_sites):
    """A spinning rotor (z translation and spin free) on ``n_sites`` cone sites: what _fill_woodbury reads of the model
    (the sites' contact, its body's coordinates)."""
    rotor = Body(0.018, [0.0, 0.0, 0.0], [False, False, True, True], load_N=[0.0, 0.0, -0.98, -0.004],
                 rotations=[(0.0, 0.0, 1.0)], inertia=[1.52e-6], brake=[1e-4])
    contact = Contact(0, law.SURFACE, "cone", (0.0, 0.0, 1.0), 0.0128, math.radians(15.0), stiffness=4e13,
                      damping=0.0, rounding_m=1e-9, friction=(0.57, 1.298, 50.0, 124.13e6, 1e-4))
    B, C, L = bodies_record([rotor], 3), contacts_record([contact]), links_record([])
    angles = 2 * math.pi * np.arange(n_sites) / n_sites
    points = np.column_stack([0.0128 * np.cos(angles), 0.0128 * np.sin(angles), np.zeros(n_sites)])
    S = sites_record(points, np.full(n_sites, 4e-7), np.zeros(n_sites, np.int64), np.zeros((n_sites * 3, 0)), C, B,
                     exclude=True)
    empty = np.zeros((0, 0))
    model = kr.Model(kr.Structure(empty, empty, empty, np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)),
                     kr.Inputs(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), 1.0, False),
                     kr.Scheme(0.25, 0.5, 0.0, 0.0), kr.Control(1e-7, 1e-7, 1e-7, 1e-14, 2.0), B, S, C, L,
                     np.zeros((0, 0)))
    return model, np.array([2, 3], np.int64)


@pytest.mark.parametrize("symmetric", [True, False])
def test_respond_through_the_inverse_equals_the_rows_of_G(symmetric):
    """u = G x for forces on one of 240 sites and on all of them: through K_eff^-1 on the scatter's support
    (_scatter_rows, _respond_inverse) against G^T's rows (_respond_rows) and numpy's G^T x, to 1e-12 relative; the
    choosing _respond takes K_eff^-1 where it is cheaper (all sites: 720 rows on |S| = 240 of 260,
    8 x 2 400 + 240 x 260 < 720 x 260, kernel.INDEXED_COST = 8) and G^T's rows where it is not (one site:
    8 x 10 + 4 x 260 > 3 x 260), bit for bit as the way it takes."""
    rng = np.random.default_rng(27 + symmetric)
    n_sites, nf, gdim = 240, 260, 3
    RF = _site_rows(rng, n_sites, nf, 240)
    invT = _inverse(rng, nf, symmetric).T
    GT = RF @ invT
    cp = kr.compliance_of(GT @ RF.T, GT, RF, invT)
    x = rng.normal(size=(n_sites, 3))
    for active, expect_inverse in ((np.arange(n_sites), True), (np.array([5]), False)):
        n_active = active.size
        loaded = np.concatenate([np.r_[3 * i:3 * i + 3] for i in active])
        reference = GT[loaded].T @ x[active].ravel()
        by_rows, by_inverse, chosen = np.empty(nf), np.empty(nf), np.empty(nf)
        kr._respond_rows(GT, active, n_active, gdim, x, by_rows)
        support = kr._scatter_rows(cp.RF, active, n_active, gdim, x, cp.g)
        np.testing.assert_allclose(cp.g, RF[loaded].T @ x[active].ravel(), rtol=RTOL, atol=0)
        assert support == np.count_nonzero(np.any(RF[loaded] != 0.0, axis=0))
        kr._respond_inverse(invT, cp.g, by_inverse)
        scale = np.abs(reference).max()
        assert np.max(np.abs(by_rows - reference)) <= RTOL * scale
        assert np.max(np.abs(by_inverse - reference)) <= RTOL * scale
        kr._respond(cp, active, n_active, gdim, x, chosen)
        np.testing.assert_array_equal(chosen, by_inverse if expect_inverse else by_rows)
    # without K_eff^-1 (a compliance given by G^T alone) the rows' way
    bare = kr.compliance_of(GT @ RF.T, GT, RF)
    kr._respond(bare, np.arange(n_sites), n_sites, gdim, x, chosen)
    kr._respond_rows(GT, np.arange(n_sites), n_sites, gdim, x, by_rows)
    np.testing.assert_array_equal(chosen, by_rows)


def _woodbury_reference(RF, invT, Fd, Fz, body_rows, active, cols, free_body, s0, gdim):
    """The Woodbury matrix of _woodbury's docstring on S, densely: [[I - R_A^T D G_A^T, -R_A^T E], [P G_A^T, Q]]
    restricted to the columns S, G^T = R_F K_eff^-T, D the active sites' Fd (block diagonal), E their Fz on the free
    body coordinates."""
    ns, nfb = cols.size, free_body.size
    rows = np.concatenate([np.r_[gdim * i:gdim * i + gdim] for i in active])
    RA = RF[rows]
    GA = (RF @ invT)[rows]
    D = np.zeros((rows.size, rows.size))
    E = np.zeros((rows.size, nfb))
    for a, k in enumerate(active):
        D[gdim * a:gdim * a + gdim, gdim * a:gdim * a + gdim] = Fd[k, :gdim, :gdim]
        E[gdim * a:gdim * a + gdim] = Fz[k][:gdim][:, free_body - s0]
    na = rows.size
    S = np.zeros((ns + nfb, ns + nfb))
    S[:ns, :ns] = np.eye(ns) - (RA.T @ D @ GA)[np.ix_(cols, cols)]
    S[:ns, ns:] = -(RA.T @ E)[cols]
    S[ns:, :ns] = body_rows[:, :na] @ GA[:, cols]
    S[ns:, ns:] = body_rows[:, na:]
    return S, RA, GA, D


@pytest.mark.parametrize("symmetric", [True, False])
def test_woodbury_through_the_inverse_equals_the_rows_of_G(symmetric):
    """The Woodbury matrix and solve on S, 236 of 240 sites active (708 rows) on |S| ~ 240 of 260 coordinates and the
    rotor's z translation and spin (a collapsed rotor's proportions: the motor's 1 536 rows on 192 of 221): through
    K_eff^-1 (B = R_A^T D R_A summed site by site, then B W; the body rows through R_A^T; the solve as R_A (W sol))
    against G^T's rows gathered on S (_fill_woodbury_rows, _woodbury_solve_rows) and against the Woodbury system
    formed densely by numpy, to 1e-12 relative; the choosing _fill_woodbury and _woodbury_solve_into take K_eff^-1
    here (the kernel's weighted counts: ~1.4 M against ~1.9 M; a solve ~64 k against ~510 k), bit for bit as that
    way."""
    rng = np.random.default_rng(41 + symmetric)
    n_sites, nf, gdim = 240, 260, 3
    model, free_body = _scene(n_sites)
    RF = _site_rows(rng, n_sites, nf, 240)
    invT = _inverse(rng, nf, symmetric).T
    GT = RF @ invT
    cp = kr.compliance_of(GT @ RF.T, GT, RF, invT)
    m = model.bodies.mass.size
    wk = kr.step_work(n_sites, gdim, m, 4, 0)
    active = rng.permutation(n_sites)[:236]          # 236 of the 240 in an iteration's order
    n_active = active.size
    wk.active[:n_active] = active
    wk.Fd[:] = rng.normal(size=wk.Fd.shape)
    wk.Fz[:] = rng.normal(size=wk.Fz.shape)
    nfb = free_body.size
    na = n_active * gdim
    body_rows = rng.normal(size=(nfb, na + nfb))
    body_rows[:, :na] *= rng.random(size=na) < 0.7        # some zero entries, as a rotor's rows have
    cols, col_pos = np.empty(nf, np.int64), np.empty(nf, np.int64)
    ns = kr._woodbury_columns(n_active, active, gdim, cp.RF, col_pos, cols)
    cols = cols[:ns]
    k = ns + nfb
    S_ref, RA, GA, D_ref = _woodbury_reference(RF, invT, wk.Fd, wk.Fz, body_rows, active, cols, free_body, 0, gdim)
    # the two ways of the matrix
    pos = np.empty(m, np.int64)
    S_rows, D_rows = np.empty((k, k)), np.empty((n_active, 3, 3))
    kr._fill_woodbury_rows(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S_rows, D_rows, pos,
                           np.empty((6, ns)))
    iw = kr.inverse_work(ns, gdim, nf, cp.RF)
    kr._gather_block(cols, invT, iw.W[:ns * ns].reshape((ns, ns)))
    S_inv, D_inv = np.empty((k, k)), np.empty((n_active, 3, 3))
    nnz_B = kr._site_products(n_active, wk, cp.RF, gdim, col_pos, ns, D_inv, iw)
    B_ref = (RA.T @ D_ref @ RA)[np.ix_(cols, cols)]
    np.testing.assert_allclose(iw.B[:ns * ns].reshape((ns, ns)), B_ref, rtol=0, atol=RTOL * np.abs(B_ref).max())
    assert nnz_B == np.count_nonzero(np.abs(B_ref) > 1e-9 * np.abs(B_ref).max())
    assert np.all(iw.mark == -1)                    # every site's marks cleared for the next
    kr._fill_woodbury_inverse(n_active, wk, cp.RF, model, free_body, body_rows, cols, col_pos, S_inv, pos, iw)
    np.testing.assert_array_equal(D_rows, D_inv)
    scale = np.abs(S_ref).max()
    assert np.max(np.abs(S_rows - S_ref)) <= RTOL * scale
    assert np.max(np.abs(S_inv - S_ref)) <= RTOL * scale
    # the choosing one takes K_eff^-1 and gathers W for the solves
    S_auto, D_auto = np.empty((k, k)), np.empty((n_active, 3, 3))
    iw_auto = kr.inverse_work(ns, gdim, nf, cp.RF)
    kr._fill_woodbury(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S_auto, D_auto, pos,
                      np.empty((6, ns)), iw_auto)
    np.testing.assert_array_equal(S_auto, S_inv)
    assert iw_auto.gathered[0] == ns
    # the solves with one matrix's factors
    LU, ipiv = np.empty(k * k), np.empty(k, np.int32)
    kr._factor(k, S_inv, LU, ipiv)
    rhs = rng.normal(size=na + nfb)
    x_rows, x_inv, x_auto = np.empty(na + nfb), np.empty(na + nfb), np.empty(na + nfb)
    kr._woodbury_solve_rows(LU, ipiv, D_inv, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x_rows,
                            np.empty(k), np.empty(k))
    kr._woodbury_solve_inverse(LU, ipiv, D_inv, cols, col_pos, active, n_active, gdim, cp.RF, body_rows, rhs, x_inv,
                               np.empty(k), np.empty(k), iw)
    kr._woodbury_solve_into(LU, ipiv, D_inv, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x_auto,
                            np.empty(k), np.empty(k), iw_auto)
    np.testing.assert_array_equal(x_auto, x_inv)
    # numpy's: the right side [R_A^T D rhs_A, rhs_b - P rhs_A], sol = S^-1 of it, x_A = rhs_A + G_A^T[:, S] sol
    small = np.concatenate([(RA.T @ D_ref @ rhs[:na])[cols], rhs[na:] - body_rows[:, :na] @ rhs[:na]])
    sol = np.linalg.solve(S_ref, small)
    reference = np.concatenate([rhs[:na] + GA[:, cols] @ sol[:ns], sol[ns:]])
    for x in (x_rows, x_inv):
        assert np.max(np.abs(x - reference)) <= 10 * RTOL * np.abs(reference).max()      # condition ~10
    # in place (x = rhs, the line search's trial solves)
    in_place = rhs.copy()
    kr._woodbury_solve_inverse(LU, ipiv, D_inv, cols, col_pos, active, n_active, gdim, cp.RF, body_rows, in_place,
                               in_place, np.empty(k), np.empty(k), iw)
    np.testing.assert_array_equal(in_place, x_inv)


def test_dense_rows_keep_the_rows_of_G():
    """A model in its free modes has dense site rows (the drill: every row on every free coordinate): the scatter
    costs what G^T's rows do, so _respond, _fill_woodbury and _woodbury_solve_into keep G^T's rows, bit for bit (the
    drill's series stay bit-identical, BENCHMARKS.md)."""
    rng = np.random.default_rng(3)
    n_sites, nf, gdim = 16, 12, 3
    model, free_body = _scene(n_sites)
    RF = rng.normal(size=(3 * n_sites, nf))
    invT = _inverse(rng, nf, False).T
    GT = RF @ invT
    cp = kr.compliance_of(GT @ RF.T, GT, RF, invT)
    x = rng.normal(size=(n_sites, 3))
    active = np.arange(n_sites)
    chosen, by_rows = np.empty(nf), np.empty(nf)
    kr._respond(cp, active, n_sites, gdim, x, chosen)
    kr._respond_rows(GT, active, n_sites, gdim, x, by_rows)
    np.testing.assert_array_equal(chosen, by_rows)
    m = model.bodies.mass.size
    wk = kr.step_work(n_sites, gdim, m, 4, 0)
    wk.active[:] = active
    wk.Fd[:] = rng.normal(size=wk.Fd.shape)
    wk.Fz[:] = rng.normal(size=wk.Fz.shape)
    na = n_sites * gdim
    body_rows = rng.normal(size=(free_body.size, na + free_body.size))
    k = nf + free_body.size
    S_auto, S_rows, D = np.empty((k, k)), np.empty((k, k)), np.empty((n_sites, 3, 3))
    cols, col_pos = np.arange(nf, dtype=np.int64), np.arange(nf, dtype=np.int64)
    pos = np.empty(m, np.int64)
    iw = kr.inverse_work(nf, gdim, nf, cp.RF)
    kr._fill_woodbury(n_sites, wk, cp, model, free_body, body_rows, cols, col_pos, S_auto, D, pos,
                      np.empty((6, nf)), iw)
    kr._fill_woodbury_rows(n_sites, wk, cp, model, free_body, body_rows, cols, col_pos, S_rows, D, pos,
                           np.empty((6, nf)))
    np.testing.assert_array_equal(S_auto, S_rows)
    LU, ipiv = np.empty(k * k), np.empty(k, np.int32)
    kr._factor(k, S_rows, LU, ipiv)
    rhs = rng.normal(size=na + free_body.size)
    x_auto, x_rows = np.empty(rhs.size), np.empty(rhs.size)
    kr._woodbury_solve_into(LU, ipiv, D, cols, col_pos, active, n_sites, gdim, cp, body_rows, rhs, x_auto,
                            np.empty(k), np.empty(k), iw)          # nf^2 + nnz_A > n_rows x nf
    kr._woodbury_solve_rows(LU, ipiv, D, cols, col_pos, active, n_sites, gdim, cp, body_rows, rhs, x_rows,
                            np.empty(k), np.empty(k))
    np.testing.assert_array_equal(x_auto, x_rows)
