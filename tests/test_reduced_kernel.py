"""The modal tier's compiled time loop (app.reduced.kernel) against closed forms of impacts.

A ball strikes a node of a stiff, heavy structure (one reduced coordinate) through a Hertz contact:
contact duration 2.9432 delta_m / v with delta_m = (5 m v^2 / (4 K))^(2/5) (Johnson, Contact
Mechanics, 11.2), rebound at the impact speed (trapezoidal rule: no numerical damping). Two rigid
bodies collide through a linear Kelvin-Voigt link: duration pi sqrt(m_eff / k), elastic rebound.
"""

import math

import numpy as np
import pytest

from app.reduced import kernel as kr
from app.contact.surface import SURFACE_KEYS, empty_surface_arrays
from forms.newmark import TimeScheme

GDIM = 2


def _empty_points():
    return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, GDIM)), np.zeros(0), np.zeros(0), np.zeros(0))


def _empty_nodes():
    return (np.zeros((0, GDIM), np.int64), np.zeros((0, GDIM)), np.zeros(0), np.zeros((0, GDIM)), np.zeros(0, np.int64),
            np.zeros(0), np.zeros(0), np.zeros(0))


def _run(t_end, structure, bodies, nodes, points, sizes, scheme, samples):
    K, M, C, fq, free_q = structure
    body_mass, body_force, zfree, z, zd = bodies
    r, m = K.shape[0], z.size
    n_contacts = nodes[-1].size + points[-1].size
    q, v, a = np.zeros(r), np.zeros(r), np.zeros(r)
    zdd = np.zeros(m)
    closed = np.zeros(n_contacts, np.bool_)
    istate = np.zeros(kr.N_ISTATE, np.int64)
    fstate = np.array([0.0, np.inf])
    cap = 100000
    out = [np.zeros(cap), np.zeros(cap), np.zeros((cap, samples.shape[0])), np.zeros((cap, 0)), np.zeros((cap, m)),
           np.zeros((cap, m)), np.zeros((cap, n_contacts)), np.zeros((cap, n_contacts), np.bool_), np.zeros((cap, 0))]
    surface = empty_surface_arrays(GDIM)
    code, rows = kr.run(t_end, q, v, a, z, zd, zdd, closed, istate, fstate, K, M, C, fq, free_q, np.zeros(0, np.int64),
                        np.zeros(0), np.zeros(0), 1.0, False, body_mass, body_force, zfree, GDIM, *nodes, *points,
                        *[surface[k] for k in SURFACE_KEYS], scheme.beta, scheme.gamma, scheme.alpha_m,
                        scheme.alpha_f, *sizes, 2.0, samples, *out)
    assert code == kr.DONE
    return rows, [o[:rows] for o in out], istate


def _contact_interval(time, closed):
    first = int(np.argmax(closed))
    last = first + int(np.argmax(~closed[first:]))
    return time[first], time[last]


def test_hertz_impact_on_a_structure_node():
    mass, speed, radius, hertz = 2.1e-3, 1.0, 0.004, 9.27e9       # the drill's ball on steel
    structure = (np.array([[1e14]]), np.array([[1e4]]), np.zeros((1, 1)), np.zeros(1), np.array([0]))
    start_gap = 1e-6
    z = np.array([0.0, -radius - start_gap])                         # below the node, moving up
    bodies = (np.array([mass]), np.zeros(GDIM), np.array([False, True]), z, np.array([0.0, speed]))
    nodes = (np.array([[-1, 0]]), np.array([[0.0, 1.0]]), np.array([start_gap]), z[None, :].copy(), np.array([0]),
             np.array([hertz]), np.array([0.0]), np.array([1.5]))
    rows, out, istate = _run(1e-4, structure, bodies, nodes, _empty_points(), (1e-6, 1e-8, 1e-9, 1e-14),
                             TimeScheme.newmark(), np.array([[1.0]]))
    time, closed, velocity = out[0], out[7][:, 0], out[5][:, 1]
    opened, closed_at = _contact_interval(time, closed)
    delta_max = (5 * mass * speed**2 / (4 * hertz)) ** 0.4
    duration = 2.9432 * delta_max / speed
    assert opened == pytest.approx(start_gap / speed, abs=1e-8)     # located to the change step
    assert closed_at - opened == pytest.approx(duration, abs=2e-8)
    assert velocity[-1] == pytest.approx(-speed, rel=1e-5)
    assert istate[kr.I_CUTBACKS] == 0
    assert np.max(out[6][:, 0]) == pytest.approx(hertz * delta_max**1.5, rel=1e-3)


def test_kelvin_voigt_collision_of_two_bodies():
    m1, m2, k, v1 = 0.04, 0.002, 5e7, 0.5
    m_eff = m1 * m2 / (m1 + m2)
    structure = (np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros(0), np.zeros(0, np.int64))
    z = np.array([0.0, 0.0, 0.0, 0.00401])                             # body 1 below body 2, touch at 0.004
    bodies = (np.array([m1, m2]), np.zeros(2 * GDIM), np.array([False, True, False, True]), z,
              np.array([0.0, v1, 0.0, 0.0]))
    points = (np.array([0]), np.array([1]), np.array([[0.0, 1.0]]), np.array([0.004]), np.array([k]), np.array([0.0]))
    rows, out, _ = _run(2e-4, structure, bodies, _empty_nodes(), points, (1e-6, 1e-8, 1e-9, 1e-14),
                        TimeScheme.newmark(), np.zeros((0, 0)))
    opened, closed_at = _contact_interval(out[0], out[7][:, 0])
    assert closed_at - opened == pytest.approx(math.pi * math.sqrt(m_eff / k), abs=2e-8)
    # elastic: velocities after the collision as for rigid balls with e = 1
    after = out[5][-1]
    assert after[1] == pytest.approx((m1 - m2) / (m1 + m2) * v1, rel=1e-6)
    assert after[3] == pytest.approx(2 * m1 / (m1 + m2) * v1, rel=1e-6)
