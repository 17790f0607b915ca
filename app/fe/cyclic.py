"""Modes of a cyclically symmetric body from one sector (modal.cyclic; docs/motor-stator.md, meshes).

A body made of N equal sectors of angle D = 360/N deg about z has modes whose field in the next sector is
the field in this one turned by D and multiplied by exp(i k D), k = 0 .. N/2 the harmonic index: the modes of
circumferential orders n = k, N - k, N + k, ... So one sector's mesh gives, for one k, exactly the modes the
whole body's mesh (the sector repeated N times) has of that k. The complex field is carried as two real
copies (a, b) = (Re, Im) of the sector's DOFs; the DOFs on the sector's end face are slaves of those on its
start face:

    [a; b]_end = R(D) [cos kD a - sin kD b;  sin kD a + cos kD b]_start

(R turns the displacement's x and y by D; u_z and the potential are scalars). With the prolongation P from
the free DOFs of both copies to all of them, the reduced operators are P^T diag(K, K) P and P^T diag(M, M) P:
real, symmetric, each mode twice (the pair (a, b) and (-b, a)) for 0 < kD < pi. Dirichlet DOFs (supports,
every electrode held at 0 V: the short circuit) are held in both copies. Serial (one process).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from app.errors import CaseError, NumericalFailure
from app.fe.eigen import shift_invert_solver


def _csr(A: PETSc.Mat) -> sp.csr_matrix:
    indptr, indices, values = A.getValuesCSR()
    return sp.csr_matrix((values, indices, indptr), shape=A.getSize())


def _petsc(A: sp.csr_matrix) -> PETSc.Mat:
    A = A.tocsr()
    A.sort_indices()
    return PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr.astype(PETSc.IntType),
                                                    A.indices.astype(PETSc.IntType), A.data), comm=PETSc.COMM_SELF)


def face_pairs(model, sector_deg: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each field (u_x, u_y, u_z, phi): (end-face DOFs, their start-face masters) in the mixed space's
    numbering, matched by turning the start face's DOF coordinates by the sector angle. The sector is the
    mesh's angular extent (less than 180 deg, not across -x)."""
    W = model.W
    V, _ = W.sub(1).collapse()
    xyz = V.tabulate_dof_coordinates()
    angles = np.arctan2(xyz[:, 1], xyz[:, 0])
    start_angle, end_angle = model.comm.allreduce(angles.min(), op=MPI.MIN), model.comm.allreduce(angles.max(),
                                                                                                   op=MPI.MAX)
    if abs(end_angle - start_angle - math.radians(sector_deg)) > 1e-9:
        raise CaseError(model.case.source, "modal.cyclic.sector_deg", f"the mesh spans "
                        f"{math.degrees(end_angle - start_angle):.6g} deg, not {sector_deg:g}")
    pairs = []
    for sub in (W.sub(0).sub(0), W.sub(0).sub(1), W.sub(0).sub(2), W.sub(1)):
        V, dofs = sub.collapse()
        dofs = np.asarray(dofs)
        xyz = V.tabulate_dof_coordinates()
        theta = np.arctan2(xyz[:, 1], xyz[:, 0])
        radius = np.hypot(xyz[:, 0], xyz[:, 1])
        tol = 1e-9 * max(1.0, radius.max())
        on_start = np.flatnonzero(np.abs(radius * np.sin(theta - start_angle)) < tol)
        on_end = np.flatnonzero(np.abs(radius * np.sin(theta - end_angle)) < tol)
        on_start = on_start[np.cos(theta[on_start] - start_angle) > 0]
        on_end = on_end[np.cos(theta[on_end] - end_angle) > 0]
        c, s = math.cos(end_angle - start_angle), math.sin(end_angle - start_angle)
        x0, y0 = xyz[on_start, 0], xyz[on_start, 1]
        turned = np.column_stack([c * x0 - s * y0, s * x0 + c * y0, xyz[on_start, 2]])
        distance, nearest = cKDTree(turned).query(xyz[on_end])
        if on_end.size != on_start.size or (distance > 1e-6 * radius.max()).any():
            raise NumericalFailure("modal.cyclic: the sector's end faces do not match (is the mesh one sector of "
                                   "geometry.parameters.sector_deg centred on 0 deg?)")
        pairs.append((dofs[on_end], dofs[on_start[nearest]], xyz[on_end]))
    if not np.allclose(pairs[0][2], pairs[1][2], rtol=0, atol=1e-12) or not np.allclose(
            pairs[0][2], pairs[2][2], rtol=0, atol=1e-12):
        raise NumericalFailure("modal.cyclic: the displacement components' DOFs do not share their nodes in order")
    return [(end, start) for end, start, _ in pairs]


def prolongation(n: int, pairs, sector_deg: float, order: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """(P: 2 n x 2 m, the free index of every DOF or -1 for a slave)."""
    slaves = np.concatenate([end for end, _ in pairs])
    free = np.ones(n, dtype=bool)
    free[slaves] = False
    index = np.full(n, -1, dtype=np.int64)
    index[free] = np.arange(free.sum())
    m = int(free.sum())
    rows, cols, vals = [], [], []
    for copy in (0, 1):                        # identity on the free DOFs of both copies
        rows.append(copy * n + np.flatnonzero(free))
        cols.append(copy * m + index[free])
        vals.append(np.ones(m))
    delta = math.radians(sector_deg)
    c_t, s_t = math.cos(delta), math.sin(delta)
    c_k, s_k = math.cos(order * delta), math.sin(order * delta)
    turn = [[(0, c_t), (1, -s_t)], [(0, s_t), (1, c_t)], [(2, 1.0)], [(3, 1.0)]]   # field f's end value from the
    for f, (end, _) in enumerate(pairs):                                           # start values of fields g
        for g, weight in turn[f]:
            master = index[pairs[g][1]]           # face_pairs aligns the components node by node
            if (master < 0).any():
                raise NumericalFailure("modal.cyclic: a start-face DOF is itself a slave (sector too thin?)")
            # a_end = w (c_k a - s_k b), b_end = w (s_k a + c_k b)
            for copy, (ca, cb) in ((0, (c_k, -s_k)), (1, (s_k, c_k))):
                rows += [copy * n + end, copy * n + end]
                cols += [master, m + master]
                vals += [np.full(end.size, weight * ca), np.full(end.size, weight * cb)]
    P = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * n, 2 * m))
    return P, index


def cyclic_modes(model, ops, cfg, target_Hz: float, n_modes: int, rigid_cutoff_Hz: float):
    """Frequencies [Hz] and real parts (full sector vectors, mass-normalised over the pair) of the modes of
    harmonic index ``cfg.order`` nearest ``target_Hz``, one per degenerate pair."""
    file = model.case.source
    if model.comm.size > 1:
        raise CaseError(file, "modal.cyclic", "runs on one process (mpirun -n 1)")
    if model.kind != "3d":
        raise CaseError(file, "modal.cyclic", "needs a 3d model (one sector of the body)")
    if model.electrodes_of("floating"):
        raise CaseError(file, "modal.cyclic", "floating electrodes break the sectors' symmetry: ground them")
    n = ops.K.getSize()[0]
    pairs = face_pairs(model, cfg.sector_deg)
    P, index = prolongation(n, pairs, cfg.sector_deg, cfg.order)
    K2 = sp.block_diag([_csr(ops.K), _csr(ops.K)], format="csr")
    M2 = sp.block_diag([_csr(ops.M), _csr(ops.M)], format="csr")
    Kr = (P.T @ K2 @ P).tocsr()
    Mr = (P.T @ M2 @ P).tocsr()
    held = np.unique(np.concatenate([model.support_dofs, model.grounded_dofs,
                                     *(model.electrode_dofs[e] for e in model.electrodes_of("ground")),
                                     *(model.electrode_dofs[e] for e in model.electrodes_of("voltage"))]))
    held = index[held]
    held = held[held >= 0]
    m = P.shape[1] // 2
    held = np.concatenate([held, held + m])
    keep = np.ones(P.shape[1])
    keep[held] = 0.0
    D = sp.diags(keep)
    Kr = (D @ Kr @ D + sp.diags(1.0 - keep)).tocsr()
    Mr = (D @ Mr @ D).tocsr()
    K_p, M_p = _petsc(Kr), _petsc(Mr)
    eps = shift_invert_solver(PETSc.COMM_SELF, K_p, M_p, 2 * n_modes, target_Hz, "modal_cyclic_")
    eps.solve()
    found = []
    y = K_p.createVecRight()
    for i in range(eps.getConverged()):
        lam = eps.getEigenpair(i, y).real
        if lam > (2 * math.pi * rigid_cutoff_Hz) ** 2:
            found.append((math.sqrt(lam) / (2 * math.pi), y.array.copy()))
    for obj in (eps, K_p, M_p, y):
        obj.destroy()
    if not found:
        raise NumericalFailure(f"modal.cyclic: no eigenpair near {target_Hz} Hz (Krylov-Schur shift-invert, MUMPS)")
    found.sort(key=lambda item: item[0])
    distinct = []
    for f, vec in found:                      # one of each degenerate pair
        if distinct and abs(f - distinct[-1][0]) <= 1e-7 * f:
            continue
        distinct.append((f, vec))
    distinct.sort(key=lambda item: abs(item[0] - target_Hz))
    distinct = sorted(distinct[:n_modes], key=lambda item: item[0])
    out = []
    for f, vec in distinct:
        full = P @ vec
        x = ops.K.createVecRight()
        x.array[:] = full[:n]
        norm = math.sqrt(abs(full @ (M2 @ full)))
        x.scale(1.0 / norm if norm > 0 else 1.0)
        out.append((f, x))
    return out
