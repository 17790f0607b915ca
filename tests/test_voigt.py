"""Voigt algebra: rotations, d-form/e-form conversion, against independent tensor calculations."""

import numpy as np
import pytest

from app.materials import LIBRARY
from forms import voigt


def _full_stiffness(c):
    """6x6 Voigt -> 3x3x3x3 tensor (independent of the Bond matrix)."""
    index = {(0, 0): 0, (1, 1): 1, (2, 2): 2, (1, 2): 3, (2, 1): 3, (0, 2): 4, (2, 0): 4, (0, 1): 5, (1, 0): 5}
    C = np.zeros((3, 3, 3, 3))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                for m in range(3):
                    C[i, j, k, m] = c[index[i, j], index[k, m]]
    return C, index


def test_bond_rotation_matches_tensor_rotation():
    c, e, eps = LIBRARY["PZT-4"].tensors()
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    C, index = _full_stiffness(c)
    C_rot = np.einsum("ia,jb,kc,ld,abcd->ijkl", q, q, q, q, C)
    c_bond = voigt.rotate_stiffness(c, q)
    for (i, j), I in index.items():
        for (k, m), J in index.items():
            assert c_bond[I, J] == pytest.approx(C_rot[i, j, k, m], rel=1e-12, abs=1e-3)
    # piezo: e_ijk = e_{i,voigt(jk)}
    E = np.zeros((3, 3, 3))
    for (j, k), J in index.items():
        E[:, j, k] = e[:, J]
    E_rot = np.einsum("ia,jb,kc,abc->ijk", q, q, q, E)
    e_bond = voigt.rotate_piezo_e(e, q)
    for (j, k), J in index.items():
        assert np.allclose(e_bond[:, J], E_rot[:, j, k], atol=1e-12)


def test_poling_frame_flips_sign_of_e33():
    _, e, _ = LIBRARY["PZT-4"].tensors()
    down = voigt.rotate_piezo_e(e, voigt.frame_from_poling((0, 0, -1)))
    assert down[2, 2] == pytest.approx(-e[2, 2])
    radial = voigt.rotate_piezo_e(e, voigt.frame_from_poling((1, 0, 0)))
    assert radial[0, 0] == pytest.approx(e[2, 2])


def test_d_form_round_trip_and_pzt4_coupling():
    c, e, eps = LIBRARY["PZT-4"].tensors()
    sE, d, epsT = voigt.e_form_to_d_form(c, e, eps)
    c2, e2, eps2 = voigt.d_form_to_e_form(sE, d, epsT)
    assert np.allclose(c2, c, rtol=1e-10)
    assert np.allclose(e2, e, rtol=1e-10, atol=1e-12)
    assert np.allclose(eps2, eps, rtol=1e-10, atol=0)         # eps ~ 6e-9 F/m: below the default atol of 1e-8
    k33 = d[2, 2] / np.sqrt(sE[2, 2] * epsT[2, 2])
    # PZT-4 datasheets give k33 ~ 0.70 and d33 ~ 290 pC/N
    assert 0.65 < k33 < 0.75
    assert 250e-12 < d[2, 2] < 320e-12
    sD = voigt.open_circuit_compliance(c, e, eps)
    assert sD[2, 2] == pytest.approx(sE[2, 2] * (1 - k33**2), rel=1e-10)
