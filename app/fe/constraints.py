"""Dirichlet constraints and floating electrodes on assembled PETSc operators.

A floating electrode (equipotential, zero net charge) is eliminated onto one master potential DOF
with a 0/1 prolongation P (x = P y): reduced operators are P^T A P (PETSc PtAP), and the zero net
charge condition is the natural one, because the master row is the sum of the electrode's rows.
Dirichlet DOFs (supports, grounded and driven electrodes) are then imposed on the reduced operator
by zeroing rows and columns (symmetry is kept, which SLEPc's GHEP needs).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class ConstraintSet:
    """Constraints of one electrical state (short-circuit, open-circuit, driven) on space ``W``."""

    def __init__(self, W, dirichlet_dofs: np.ndarray, floating_groups: list[np.ndarray]):
        self.W = W
        self.comm = W.mesh.comm
        imap = W.dofmap.index_map
        bs = W.dofmap.index_map_bs
        assert bs == 1, "mixed spaces have block size 1"
        self.n_owned = imap.size_local
        self.n_local = imap.size_local + imap.num_ghosts
        self.rstart = imap.local_range[0]
        self.n_global = imap.size_global
        self.local_to_global = imap.local_to_global(np.arange(self.n_local, dtype=np.int32))
        self.dirichlet_local = np.unique(dirichlet_dofs[dirichlet_dofs < self.n_owned]).astype(np.int32)
        self.P = self._prolongation(floating_groups) if floating_groups else None

    def _prolongation(self, groups: list[np.ndarray]) -> PETSc.Mat:
        """0/1 matrix mapping reduced DOFs (one per floating electrode) to full DOFs."""
        comm = self.comm
        big = np.iinfo(np.int64).max
        slave_owned = np.zeros(self.n_owned, dtype=bool)
        masters = []
        for dofs in groups:
            globals_ = self.local_to_global[dofs]
            master = comm.allreduce(int(globals_.min()) if globals_.size else big, op=MPI.MIN)
            masters.append(master)
            owned = dofs[dofs < self.n_owned]
            slave_owned[owned[self.local_to_global[owned] != master]] = True
        keep = ~slave_owned
        n_red_local = int(keep.sum())
        offset = comm.exscan(n_red_local) or 0
        reduced_index = np.full(self.n_owned, -1, dtype=np.int64)
        reduced_index[keep] = offset + np.arange(n_red_local)
        master_reduced = []
        for master in masters:
            local = master - self.rstart
            value = int(reduced_index[local]) if 0 <= local < self.n_owned else -1
            master_reduced.append(comm.allreduce(value, op=MPI.MAX))
        columns = reduced_index.copy()
        for dofs, m_red in zip(groups, master_reduced):
            owned = dofs[dofs < self.n_owned]
            columns[owned] = m_red
        self.n_reduced_global = comm.allreduce(n_red_local)
        self.reduced_rstart = offset
        self.n_reduced_local = n_red_local
        self.keep_owned = keep
        self.reduced_of_owned = columns
        P = PETSc.Mat().createAIJ(((self.n_owned, self.n_global), (n_red_local, self.n_reduced_global)),
                                  nnz=(1, 1), comm=comm)
        P.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        rows = self.rstart + np.arange(self.n_owned, dtype=np.int32)
        for row, col in zip(rows, columns):
            P.setValue(int(row), int(col), 1.0)
        P.assemble()
        return P

    # -- operators and vectors in the reduced space ------------------------------------------------
    def reduce(self, A: PETSc.Mat) -> PETSc.Mat:
        """P^T A P (or a copy of A when nothing floats)."""
        if self.P is None:
            return A.copy()
        return A.PtAP(self.P)

    def reduce_vector(self, x: PETSc.Vec) -> PETSc.Vec:
        if self.P is None:
            return x.copy()
        y = self.P.createVecRight()
        self.P.multTranspose(x, y)
        return y

    def expand(self, y: PETSc.Vec, out: PETSc.Vec) -> None:
        """Full vector from a reduced one (floating electrodes get their master's value)."""
        if self.P is None:
            y.copy(out)
        else:
            self.P.mult(y, out)

    def dirichlet_rows(self) -> np.ndarray:
        """Global indices (reduced numbering) of the owned Dirichlet DOFs."""
        if self.P is None:
            return (self.rstart + self.dirichlet_local).astype(np.int32)
        return self.reduced_of_owned[self.dirichlet_local].astype(np.int32)

    def apply(self, A: PETSc.Mat, diagonal: float, x_bc: PETSc.Vec | None = None,
              b: PETSc.Vec | None = None) -> None:
        """Zero Dirichlet rows/columns of reduced ``A``; with ``x_bc`` and ``b``, lift the prescribed
        values into ``b`` (b -= A[:, D] x_D; b[D] = diagonal x_D)."""
        A.zeroRowsColumns(self.dirichlet_rows(), diag=diagonal, x=x_bc, b=b)
