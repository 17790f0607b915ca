"""Voigt-notation tensor algebra (IEEE order xx, yy, zz, yz, xz, xy) for piezoelectric data.

Functions accept numpy arrays; the rotation helpers also accept UFL matrices, which is how a
poling direction that varies in space (a radially poled tube in 3D) enters the forms.
"""

from __future__ import annotations

import numpy as np
import ufl


def _as(obj, rows):
    return ufl.as_matrix(rows) if isinstance(obj, ufl.core.expr.Expr) else np.array(rows, dtype=float)


def bond_stress_matrix(a):
    """6x6 Bond matrix M for rotation ``a`` (a[i, j] = global_i . local_j): T_global = M T_local,
    c_global = M c_local M^T, e_global = a e_local M^T (Auld, Acoustic Fields and Waves)."""
    A = [[a[i, j] for j in range(3)] for i in range(3)]
    rows = [[A[i][0] ** 2, A[i][1] ** 2, A[i][2] ** 2, 2 * A[i][1] * A[i][2], 2 * A[i][2] * A[i][0],
             2 * A[i][0] * A[i][1]] for i in range(3)]
    pairs = ((1, 2), (2, 0), (0, 1))
    for i, k in pairs:
        rows.append([
            A[i][0] * A[k][0], A[i][1] * A[k][1], A[i][2] * A[k][2],
            A[i][1] * A[k][2] + A[i][2] * A[k][1],
            A[i][0] * A[k][2] + A[i][2] * A[k][0],
            A[i][1] * A[k][0] + A[i][0] * A[k][1],
        ])
    return _as(a, rows)


def _ufl(t):
    return t if isinstance(t, ufl.core.expr.Expr) else ufl.as_matrix(np.asarray(t).tolist())


def rotate_stiffness(c, a):
    """Elastic stiffness [Pa] from the material frame to the global frame."""
    M = bond_stress_matrix(a)
    if isinstance(a, ufl.core.expr.Expr):
        return ufl.dot(ufl.dot(M, _ufl(c)), M.T)
    return M @ c @ M.T


def rotate_piezo_e(e, a):
    """Piezoelectric stress constants e [C/m^2] (3x6) to the global frame."""
    M = bond_stress_matrix(a)
    if isinstance(a, ufl.core.expr.Expr):
        return ufl.dot(ufl.dot(a, _ufl(e)), M.T)
    return np.asarray(a) @ e @ M.T


def rotate_permittivity(eps, a):
    """Permittivity [F/m] (3x3) to the global frame."""
    if isinstance(a, ufl.core.expr.Expr):
        return ufl.dot(ufl.dot(a, _ufl(eps)), a.T)
    return np.asarray(a) @ eps @ np.asarray(a).T


def frame_from_poling(p) -> np.ndarray:
    """Rotation (columns = material axes 1, 2, 3 in global coordinates) whose axis 3 is the unit
    poling vector ``p``. Transversely isotropic (6mm) materials do not depend on the choice of
    axes 1 and 2, so any right-handed completion is used."""
    p = np.asarray(p, dtype=float)
    p = p / np.linalg.norm(p)
    helper = np.array([1.0, 0.0, 0.0]) if abs(p[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = helper - (helper @ p) * p
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(p, e1)
    return np.column_stack([e1, e2, p])


def radial_frame_3d(x):
    """UFL rotation for radial poling about the global z axis at spatial point ``x``:
    material axis 3 = e_r, axis 2 = e_theta, axis 1 = -e_z (right-handed)."""
    rho = ufl.sqrt(x[0] ** 2 + x[1] ** 2)
    c, s = x[0] / rho, x[1] / rho
    return ufl.as_matrix([[0, -s, c], [0, c, s], [-1, 0, 0]])


def isotropic_stiffness(young_Pa: float, poisson: float) -> np.ndarray:
    """6x6 stiffness of an isotropic solid [Pa]."""
    lam = young_Pa * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = young_Pa / (2 * (1 + poisson))
    c = np.zeros((6, 6))
    c[:3, :3] = lam
    c[np.arange(3), np.arange(3)] = lam + 2 * mu
    c[np.arange(3, 6), np.arange(3, 6)] = mu
    return c


def transversely_isotropic_stiffness(c11, c12, c13, c33, c44, c66=None) -> np.ndarray:
    """6x6 stiffness of a 6mm (poled ceramic) material with axis 3 the poling axis [Pa]."""
    c66 = 0.5 * (c11 - c12) if c66 is None else c66
    return np.array([
        [c11, c12, c13, 0, 0, 0],
        [c12, c11, c13, 0, 0, 0],
        [c13, c13, c33, 0, 0, 0],
        [0, 0, 0, c44, 0, 0],
        [0, 0, 0, 0, c44, 0],
        [0, 0, 0, 0, 0, c66],
    ], dtype=float)


def piezo_e_6mm(e31, e33, e15) -> np.ndarray:
    """3x6 piezoelectric stress constants of a 6mm material [C/m^2]."""
    e = np.zeros((3, 6))
    e[0, 4] = e[1, 3] = e15
    e[2, 0] = e[2, 1] = e31
    e[2, 2] = e33
    return e


def d_form_to_e_form(sE: np.ndarray, d: np.ndarray, epsT: np.ndarray):
    """Strain-charge data (s^E [1/Pa], d [C/N], eps^T [F/m]) to stress-charge data
    (c^E, e = d c^E, eps^S = eps^T - d c^E d^T)."""
    cE = np.linalg.inv(sE)
    e = d @ cE
    epsS = epsT - d @ cE @ d.T
    return cE, e, epsS


def e_form_to_d_form(cE: np.ndarray, e: np.ndarray, epsS: np.ndarray):
    """Inverse of :func:`d_form_to_e_form`: (s^E, d, eps^T)."""
    sE = np.linalg.inv(cE)
    d = e @ sE
    epsT = epsS + d @ cE @ d.T
    return sE, d, epsT


def open_circuit_compliance(cE: np.ndarray, e: np.ndarray, epsS: np.ndarray) -> np.ndarray:
    """s^D = (c^D)^-1 with c^D = c^E + e^T (eps^S)^-1 e [1/Pa]."""
    cD = cE + e.T @ np.linalg.solve(epsS, e)
    return np.linalg.inv(cD)
