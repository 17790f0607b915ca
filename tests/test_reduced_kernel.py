"""The modal tier's compiled time loop (app/reduced/kernel.py) and the contact law at a site
(app/contact/law.py) against closed forms and finite differences.

* A ball strikes a node of a stiff, heavy structure (one reduced coordinate) through a Hertz contact: contact
  duration 2.9432 delta_m / v with delta_m = (5 m v^2 / (4 K))^(2/5) (Johnson, Contact Mechanics, 11.2),
  rebound at the impact speed (trapezoidal rule: no numerical damping).
* Two rigid bodies collide through a linear Kelvin-Voigt link: duration pi sqrt(m_eff / k), elastic rebound.
* A site's force derivatives (the site's own increment, its body's translations and spin) equal central
  differences for every obstacle shape, damped, in stick and in slip, on a spinning body: the Newton
  iteration's quadratic convergence rests on them. So does the assembled Newton matrix of the condensed
  step (active sites + body corrections), checked against differences of the residual.
"""

import math

import numpy as np
import pytest
from reduced_scene import Body, Contact, Link, bodies_record, contacts_record, links_record, run, sites_record

from app.contact import law
from app.reduced import kernel as kr
from forms.newmark import TimeScheme


class Sizes:
    open_s, closed_s, change_s, min_s = 1e-6, 1e-8, 1e-9, 1e-14


def _contact_interval(time, closed):
    first = int(np.argmax(closed))
    last = first + int(np.argmax(~closed[first:]))
    return time[first], time[last]


def test_hertz_impact_on_a_structure_node():
    mass, speed, radius, hertz = 2.1e-3, 1.0, 0.004, 9.27e9       # the drill's ball on steel
    start_gap = 1e-6
    K, M = np.array([[1e14]]), np.array([[1e4]])
    ball = Body(mass, [0.0, -radius - start_gap], [False, True], velocity=[0.0, speed])
    contact = Contact(body=0, kind=law.NODE, shape="sphere", vector=(0.0, 1.0, 0.0), radius_m=radius,
                      stiffness=hertz, exponent=1.5)
    C, B = contacts_record([contact]), bodies_record([ball], 2)
    # the node at the origin, its z displacement the structure's one coordinate
    sites = sites_record([[0.0, 0.0, 0.0]], [1.0], [0], np.array([[0.0], [1.0]]), C, B)
    records, istate = run(K, M, np.zeros((1, 1)), [0.0], [0.0], [0.0], [ball], 2, sites, [contact], [],
                          TimeScheme.newmark(), Sizes, 1e-4)
    time = np.array([r["time_s"] for r in records])
    closed = np.array([r["contact_closed"][0] for r in records]) > 0
    velocity = np.array([r["velocity_m_per_s"][1] for r in records])
    force = np.array([np.linalg.norm(r["contact_force_N"]["c0"]) for r in records])
    opened, closed_at = _contact_interval(time, closed)
    delta_max = (5 * mass * speed**2 / (4 * hertz)) ** 0.4
    duration = 2.9432 * delta_max / speed
    assert opened == pytest.approx(start_gap / speed, abs=1e-8)     # located to the change step
    assert closed_at - opened == pytest.approx(duration, abs=2e-8)
    assert velocity[-1] == pytest.approx(-speed, rel=1e-5)
    assert istate[kr.I_CUTBACKS] == 0
    assert np.max(force) == pytest.approx(hertz * delta_max**1.5, rel=1e-3)


def test_kelvin_voigt_collision_of_two_bodies():
    m1, m2, k, v1 = 0.04, 0.002, 5e7, 0.5
    m_eff = m1 * m2 / (m1 + m2)
    lower = Body(m1, [0.0, 0.0], [False, True], velocity=[0.0, v1])
    upper = Body(m2, [0.0, 0.00401], [False, True])
    link = Link(0, 1, (0.0, 1.0, 0.0), 0.004, k)
    empty = np.zeros((0, 0))
    records, _ = run(empty, empty, empty, [], [], [], [lower, upper], 2, None, [], [link], TimeScheme.newmark(), Sizes,
                     2e-4)
    time = np.array([r["time_s"] for r in records])
    closed = np.array([r["contact_closed"][0] for r in records]) > 0
    opened, closed_at = _contact_interval(time, closed)
    assert closed_at - opened == pytest.approx(math.pi * math.sqrt(m_eff / k), abs=2e-8)
    # elastic: velocities after the collision as for rigid balls with e = 1
    after = records[-1]["velocity_m_per_s"]
    assert after[1] == pytest.approx((m1 - m2) / (m1 + m2) * v1, rel=1e-6)
    assert after[3] == pytest.approx(2 * m1 / (m1 + m2) * v1, rel=1e-6)


# ------------------------------------------------------------------ derivatives against differences
SHAPE_CASES = {
    # shape, vector, radius, half angle, the site relative to the body's reference point
    "plane": ("plane", (0.0, 0.0, 1.0), 0.0, 0.0, (3e-3, -2e-3, -2e-8)),
    "sphere": ("sphere", (0.0, 0.0, 0.0), 4e-3, 0.0, (1e-3, 0.5e-3, 3.84e-3)),
    "sphere-pole": ("sphere", (0.0, 0.0, 1.0), 4e-3, 0.0, (1e-3, 0.5e-3, 3.84e-3)),
    "cone": ("cone", (0.0, 0.0, 1.0), 0.0128, math.radians(15.0), (0.0128, 0.0, 0.0)),
}


def _site_scene(shape_key, slip, friction, spinning):
    shape, vector, radius, half, point = SHAPE_CASES[shape_key]
    rotations = [(0.0, 0.0, 1.0)] if spinning else []
    body = Body(0.018, [0.0, 0.0, 0.0], [True, True, True] + [True] * len(rotations), rotations=rotations,
                inertia=[1.5e-6] * len(rotations))
    contact = Contact(0, law.SURFACE, shape, vector, radius, half, stiffness=4e13, damping=3e5, rounding_m=1e-9,
                      friction=(0.57, 1.298, 50.0, 124.13e6, 1e-4) if friction else (0.0, 1.0, 0.0, 1e20, 1e-4))
    B, C = bodies_record([body], 3), contacts_record([contact])
    S = sites_record([point], [4e-7], [0], np.zeros((3, 0)), C, B)
    rng = np.random.default_rng(3)
    y = rng.normal(size=3) * 1e-9
    if shape_key == "cone":         # into the cone face: along its outward normal, inwards
        y = np.array([-3e-8, 1e-9, 2e-9])
    v = rng.normal(size=3) * slip
    m = B.mass.size
    z_mid, zd_mid = np.zeros(m), np.zeros(m)
    zd_mid[:3] = rng.normal(size=3) * slip * 0.3
    if spinning:       # fast enough that the spin's share of the slip, omega x (the site's move), shows
        zd_mid[3] = 3e5
    return S, C, B, y, v, z_mid, zd_mid


@pytest.mark.parametrize("spinning", [False, True])
@pytest.mark.parametrize("friction,slip", [(False, 1e-3), (True, 1e-5), (True, 3e-2)], ids=["frictionless", "stick",
                                                                                          "slip"])
@pytest.mark.parametrize("shape_key", list(SHAPE_CASES))
def test_site_force_derivatives_equal_differences(shape_key, friction, slip, spinning):
    S, C, B, y, v, z_mid, zd_mid = _site_scene(shape_key, slip, friction, spinning)
    c_vel, w_f = 2.9e6, 0.75
    work = law.site_work(B.mass.size)
    fn, gap, *_ = law.site_force(0, y, v, z_mid, zd_mid, S, C, B, c_vel, w_f, True, work)
    assert fn > 0 and gap < 0
    Fd, Fz = work.Fd.copy(), work.Fz[:, :B.mass.size].copy()

    def force(dd, dz):
        """f at the site increment dd and body increments dz (the mid-point and rate factors applied)."""
        w = law.site_work(B.mass.size)
        law.site_force(0, y + w_f * dd, v + w_f * c_vel * dd, z_mid + w_f * dz, zd_mid + w_f * c_vel * dz, S, C, B,
                       c_vel, w_f, False, w)
        return w.f.copy()

    h = 1e-13          # a displacement increment [m]: 1e-6 of the penetration, well above its round-off
    numeric = np.column_stack([(force(e * h, 0 * z_mid) - force(-e * h, 0 * z_mid)) / (2 * h) for e in np.eye(3)])
    scale = np.abs(numeric).max()
    np.testing.assert_allclose(Fd, numeric, rtol=2e-4, atol=2e-4 * scale)
    numeric_z = np.column_stack([(force(np.zeros(3), e * h) - force(np.zeros(3), -e * h)) / (2 * h)
                                 for e in np.eye(B.mass.size)])
    np.testing.assert_allclose(Fz, numeric_z, rtol=2e-4, atol=2e-4 * max(scale, np.abs(numeric_z).max()))


def test_newton_matrix_equals_differences_of_the_residual():
    """The condensed step on a cone (the motor's geometry): 6 sites round a ring on a spinning, translating rotor,
    some in contact, friction in stick and slip; the Newton matrix on the active sites and the free body
    corrections against central differences of the residuals, with a random SPD compliance H."""
    rng = np.random.default_rng(11)
    n_sites, gdim = 6, 3
    alpha = math.radians(15.0)
    rotor = Body(0.018, [0.0, 0.0, 0.0], [False, False, True, True], load_N=[0.0, 0.0, -0.98, -0.004],
                 rotations=[(0.0, 0.0, 1.0)], inertia=[1.52e-6], brake=[1e-4])
    contact = Contact(0, law.SURFACE, "cone", (0.0, 0.0, 1.0), 0.0128, alpha, stiffness=4e13, damping=0.0,
                      rounding_m=1e-9, friction=(0.57, 1.298, 50.0, 124.13e6, 1e-4))
    B, C, L = bodies_record([rotor], 3), contacts_record([contact]), links_record([])
    angles = 2 * math.pi * np.arange(n_sites) / n_sites
    points = np.column_stack([0.0128 * np.cos(angles), 0.0128 * np.sin(angles), np.zeros(n_sites)])
    S = sites_record(points, np.full(n_sites, 4e-7), np.zeros(n_sites, np.int64), np.zeros((n_sites * 3, 0)), C, B,
                     exclude=True)
    nr = n_sites * gdim
    A = rng.normal(size=(nr, nr))
    H = 1e-9 * (A @ A.T / nr + np.eye(nr))
    scheme = (0.25, 0.5, 0.0, 0.0)
    dt = 6.93e-7
    m = B.mass.size
    wk = kr.step_work(n_sites, gdim, m, 4, 0)
    normals = np.column_stack([math.cos(alpha) * np.cos(angles), math.cos(alpha) * np.sin(angles),
                               np.full(n_sites, -math.sin(alpha))])
    depth = np.where(np.arange(n_sites) % 2 == 0, -3e-8, 1e-8)          # half the sites 30 nm inside
    wk.y0[:] = depth[:, None] * normals
    wk.v0[:] = rng.normal(size=(n_sites, 3)) * 1e-3
    wk.a0[:] = rng.normal(size=(n_sites, 3)) * 10.0
    wk.dw[:] = rng.normal(size=nr) * 1e-10
    z0, zd0, zdd0 = np.zeros(m), np.array([0.0, 0.0, 1e-4, 3.0]), np.array([0.0, 0.0, -50.0, 0.0])
    state = kr.State(np.zeros(0), np.zeros(0), np.zeros(0), z0, zd0, zdd0, np.zeros(kr.N_ISTATE, np.int64),
                     np.zeros(kr.N_FSTATE), kr.Sums(np.zeros(1), np.zeros(1), np.zeros(2)), np.zeros((n_sites, 3)))
    empty = np.zeros((0, 0))
    model = kr.Model(kr.Structure(empty, empty, empty, np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)),
                     kr.Inputs(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), 1.0, False),
                     kr.Scheme(*scheme), kr.Control(dt, dt, dt, 1e-14, 2.0), B, S, C, L, np.zeros((0, 0)))
    free_body = np.array([2, 3], np.int64)
    compliance = kr.dense_compliance(H)          # the sites are the coordinates: H f = G f

    def residual(dd, xi, want=False):
        n_active = kr._evaluate(dd, xi, wk, compliance, state, dt, model, want)
        return n_active, wk.R.copy(), wk.rz.copy()

    dd0 = wk.dw + rng.normal(size=nr) * 1e-10
    xi0 = np.array([0.0, 0.0, 2e-12, 1e-10])
    n_active, R, rz = residual(dd0, xi0, True)
    assert 0 < n_active < n_sites
    J, rhs = kr._newton_matrix(n_active, wk, compliance, model, free_body, dt)
    active = wk.active[:n_active].copy()
    rows = np.concatenate([np.r_[3 * i:3 * i + 3] for i in active])

    def vector(dd, xi):
        _, R_, rz_ = residual(dd, xi)
        return np.concatenate([R_[rows], rz_[free_body]])

    np.testing.assert_allclose(-rhs, vector(dd0, xi0), rtol=1e-12, atol=1e-30)
    N = rhs.size
    numeric = np.zeros((N, N))
    for col in range(N):
        dd, xi = dd0.copy(), xi0.copy()
        if col < rows.size:
            h = 1e-13
            dd[rows[col]] += h
            up = vector(dd, xi)
            dd[rows[col]] -= 2 * h
            down = vector(dd, xi)
        else:
            j = free_body[col - rows.size]
            h = 1e-13
            xi[j] += h
            up = vector(dd, xi)
            xi[j] -= 2 * h
            down = vector(dd, xi)
        numeric[:, col] = (up - down) / (2 * h)
    column_scale = np.abs(numeric).max(axis=0)
    assert np.max(np.abs(J - numeric) / column_scale) < 1e-3

    # The same Newton system solved in the structure's coordinates (app/reduced/kernel.py:_woodbury, taken when
    # many sites are active) on a compliance with sparse site rows, R_F (nr x 10, three entries a row), and
    # K_eff^-1 SPD: against the contact-space LU of the same J. Both are exact algebra on a system of condition
    # ~1e2, so they agree to round-off; 1e-9 catches a wrong sign or a missed block (of order one).
    nf = 10
    RF = np.zeros((nr, nf))
    for r in range(nr):
        RF[r, rng.choice(nf, 3, replace=False)] = rng.normal(size=3)
    B_ = rng.normal(size=(nf, nf))
    K_inv = 1e-9 * (B_ @ B_.T / nf + np.eye(nf))
    GT = RF @ K_inv
    sparse = kr.compliance_of(GT @ RF.T, GT, RF, K_inv)
    n_active = kr._evaluate(dd0, xi0, wk, sparse, state, dt, model, True)
    assert 0 < n_active < n_sites
    J, rhs = kr._newton_matrix(n_active, wk, sparse, model, free_body, dt)
    body_rows, rhs_b = kr._newton_matrix(n_active, wk, sparse, model, free_body, dt, False)
    np.testing.assert_array_equal(body_rows, J[n_active * gdim:])
    factors, D, cols, col_pos, iw = kr._woodbury(n_active, wk, sparse, model, free_body, body_rows, True)
    x = kr._woodbury_solve(factors, D, cols, col_pos, wk.active[:n_active].copy(), n_active, gdim, sparse, body_rows,
                           rhs_b, iw)
    reference = np.linalg.solve(J, rhs)
    scale = np.concatenate([np.full(n_active * gdim, np.abs(reference[:n_active * gdim]).max()),
                            np.abs(reference[n_active * gdim:])])
    assert np.max(np.abs(x - reference) / scale) < 1e-9

    def newton_both_ways(compliance_, GT, RF):
        """The whole Newton iteration with every site pressed in, on ``compliance_`` and on the same H given densely
        (the contact-space LU): (iterations of each, whether each took the Woodbury system), the solutions checked
        equal to the iteration's tolerances (1e-14 m or 1e-9 of a site increment, 1e-10 of the body's force scale;
        1e-6 catches a wrong or stale system, order one), and |S| of the K_eff^-1 block the last matrix gathered."""
        wk.y0[:] = -3e-8 * normals
        solutions = []
        for c in (compliance_, kr.dense_compliance(GT @ RF.T)):
            nw = kr.newton_work(n_sites, gdim, m, c.GT.shape[1], c.RF)
            wk.dd[:] = wk.dw
            wk.xi[:] = 0.0
            converged, its = kr._newton(wk, nw, c, state, dt, model, free_body)
            assert converged and its > 1
            solutions.append((wk.dd.copy(), wk.xi.copy(), bool(np.any(nw.S_LU != 0.0)), its,
                              int(nw.inverse.gathered[0]) if nw.inverse.gathered.size else -1))
        (dd_w, xi_w, woodbury, its_w, gathered), (dd_c, xi_c, dense_woodbury, its_c, _) = solutions
        np.testing.assert_allclose(dd_w, dd_c, rtol=1e-6, atol=1e-13)
        np.testing.assert_allclose(xi_w, xi_c, rtol=1e-6, atol=1e-16)
        # gathered: |S| where the last Woodbury matrix gathered K_eff^-1's block for the solves (-1: not)
        return (its_w, its_c), (woodbury, dense_woodbury), gathered

    # The whole Newton iteration (app/reduced/kernel.py:_newton, compiled without reference counts, its arrays in a
    # NewtonWork) with every site pressed in: on the sparse compliance it takes the Woodbury path (3 x 6 active
    # rows > 1.5 x the 10 free coordinates they touch), on the same H given densely (the sites as 18 free
    # coordinates) the contact-space LU. The same equations, so the same solution to the iteration's tolerances
    # (1e-14 m or 1e-9 of a site increment, 1e-10 of the body's force scale); 1e-6 catches a wrong or stale system
    # (order one).
    its, woodbury, _ = newton_both_ways(sparse, GT, RF)
    assert woodbury == (True, False)

    # The Woodbury system restricted to the coordinates S the active sites' rows touch (_woodbury_columns): exact,
    # since every R_A^T x lives on S. Site rows as the motor's "interface" sites have them, a few nonzeros on a
    # structure of many more free coordinates: here site i's three rows on 2 of nf = 40 coordinates, shared with its
    # neighbour (columns c_i, c_i+1), so S has 6 of the 40 however many sites are active. Against the contact-space
    # LU of the same J (1e-9 as above), the restricted against the full system too; a column missing from S
    # (a row of R_A^T written into another row) breaks both by order one.
    nf = 40
    ring = rng.choice(nf, n_sites, replace=False)
    RF = np.zeros((nr, nf))
    for i in range(n_sites):
        RF[3 * i:3 * i + 3, [ring[i], ring[(i + 1) % n_sites]]] = rng.normal(size=(3, 2))
    B_ = rng.normal(size=(nf, nf))
    K_inv = 1e-9 * (B_ @ B_.T / nf + np.eye(nf))
    GT = RF @ K_inv
    local = kr.compliance_of(GT @ RF.T, GT, RF, K_inv)      # G x, the Woodbury system through K_inv where cheaper
    wk.y0[:] = depth[:, None] * normals
    n_active = kr._evaluate(dd0, xi0, wk, local, state, dt, model, True)
    assert 0 < n_active < n_sites
    J, rhs = kr._newton_matrix(n_active, wk, local, model, free_body, dt)
    body_rows, rhs_b = kr._newton_matrix(n_active, wk, local, model, free_body, dt, False)
    reference = np.linalg.solve(J, rhs)
    scale = np.concatenate([np.full(n_active * gdim, np.abs(reference[:n_active * gdim]).max()),
                            np.abs(reference[n_active * gdim:])])
    active = wk.active[:n_active].copy()
    touched = np.flatnonzero(np.any(RF[np.concatenate([np.r_[3 * i:3 * i + 3] for i in active])] != 0.0, axis=0))
    for full in (False, True):
        factors, D, cols, col_pos, iw = kr._woodbury(n_active, wk, local, model, free_body, body_rows, full)
        np.testing.assert_array_equal(cols, np.arange(nf) if full else touched)
        assert factors[1].size == cols.size + free_body.size
        x = kr._woodbury_solve(factors, D, cols, col_pos, active, n_active, gdim, local, body_rows, rhs_b, iw)
        assert np.max(np.abs(x - reference) / scale) < 1e-9

    # And the whole Newton iteration with every site pressed in: 18 active rows on |S| = 6 coordinates take the
    # restricted system (18 > 1.5 x 6, where the full one, 18 > 1.5 x 40, was not taken), against the contact-space
    # LU of the same H given densely; the tolerances as above. The same Newton steps to round-off, so the same
    # iterations too (a wrong matrix still converges, by the residual, but not in Newton's count).
    its, woodbury, gathered = newton_both_ways(local, GT, RF)
    assert woodbury == (True, False)
    assert its[0] == its[1]
    # ... the solves through K_eff^-1 (the compliance carries it; 6 x 6 + 3 x 36 < 3 x 18 x 6 weighted products a
    # solve, kernel.GATHER_COST = 3: tests/test_reduced_kernel_inv.py checks those products one by one)
    assert gathered == 6


@pytest.mark.parametrize("size", [1, 2, 7, 64, 221])
def test_woodbury_factors_solve_as_lapack_does(size):
    """The Woodbury system's LU factors (:func:`_factor`, LAPACK getrf) and the triangular solves written in the kernel
    (:func:`_lu_apply`, getrs' steps) against numpy's solve (gesv: the same factors), on matrices that need row
    interchanges (a permuted diagonal-dominant matrix: every pivot moves a row) and the size of the collapsed motor's
    system (221): equal to 1e-12 relative (round-off of two triangular sweeps at condition numbers ~10). Reading
    the interchanges backwards, or the factors as C order, fails it."""
    rng = np.random.default_rng(size)
    S = (np.eye(size) * 4 + rng.uniform(-1, 1, (size, size)))[rng.permutation(size)]
    b = rng.standard_normal(size)
    LU, ipiv = np.empty(size * size), np.empty(size, np.int32)
    kr._factor(size, S, LU, ipiv)
    x = np.empty(size)
    kr._lu_apply(size, LU, ipiv, b, x)
    expected = np.linalg.solve(S, b)
    assert np.max(np.abs(x - expected)) <= 1e-12 * np.max(np.abs(expected))
    if size >= 7:
        assert np.any(ipiv != np.arange(1, size + 1))          # the matrix made the factorisation interchange rows
