"""Small dense matrix functions in numba, bit-for-bit independent of the BLAS thread count.

scipy's expm and numpy's matmul go through OpenBLAS, whose results for a 14 x 14 product change in
the last bit with the number of threads (e.g. under mpirun, where ranks are pinned to one core).
The drill motion is sensitive to round-off, so a sweep would give a different table on 1 and on 2
ranks. These loops fix the order of every floating-point operation.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def matmul(a, b):
    n, m = a.shape
    p = b.shape[1]
    out = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            aik = a[i, k]
            if aik != 0.0:
                for j in range(p):
                    out[i, j] += aik * b[k, j]
    return out


@njit(cache=True)
def expm(m):
    """exp(M) by scaling and squaring with a Taylor series (|M / 2^s|_1 <= 1/2, terms to 1e-18).

    Accurate for well-scaled M; callers balance the state so that entries are ~ omega h."""
    n = m.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(m[i, j])
        norm = max(norm, col)
    squarings = 0
    while norm > 0.5:
        norm *= 0.5
        squarings += 1
    scaled = m / 2.0**squarings
    result = np.eye(n)
    term = np.eye(n)
    for k in range(1, 60):
        term = matmul(term, scaled) / k
        result += term
        if np.max(np.abs(term)) <= 1e-18 * np.max(np.abs(result)):
            break
    for _ in range(squarings):
        result = matmul(result, result)
    return result


@njit(cache=True)
def mode_caches(b, q, step_s, levels, direct_every):
    """For one contact state with (balanced) matrix B and ledger forms Q (k, n, n): at every dyadic
    level j (step h / 2^j) exp(B h_j), the Gramians int_0^h_j e^{B^T s} Q_k e^{B s} ds and
    int_0^h_j e^{B s} ds.

    Exponentials: directly at every ``direct_every``-th level, between by squaring the next finer one.
    Gramians and integrals: Van Loan's block exponential at the finest level, then doubled upwards,
    G(2s) = G(s) + E(s)^T G(s) E(s), Phi(2s) = Phi(s) + E(s) Phi(s)."""
    n = b.shape[0]
    nq = q.shape[0]
    ex = np.zeros((levels + 1, n, n))
    gram = np.zeros((levels + 1, nq, n, n))
    phi = np.zeros((levels + 1, n, n))
    for level in range(levels, -1, -1):
        if level % direct_every == 0 or level == levels:
            ex[level] = expm(b * (step_s / 2.0**level))
        else:
            ex[level] = matmul(ex[level + 1], ex[level + 1])
    finest = step_s / 2.0**levels
    block = np.zeros((2 * n, 2 * n))
    for k in range(nq):
        block[:, :] = 0.0
        block[:n, :n] = -b.T
        block[:n, n:] = q[k]
        block[n:, n:] = b
        f = expm(block * finest)
        gram[levels, k] = matmul(f[n:, n:].T.copy(), f[:n, n:].copy())
    block[:, :] = 0.0
    block[:n, :n] = b
    block[:n, n:] = np.eye(n)
    phi[levels] = expm(block * finest)[:n, n:]
    for level in range(levels - 1, -1, -1):
        e = ex[level + 1]
        et = e.T.copy()
        for k in range(nq):
            g = gram[level + 1, k]
            gram[level, k] = g + matmul(matmul(et, g), e)
        phi[level] = phi[level + 1] + matmul(e, phi[level + 1])
    return ex, gram, phi
