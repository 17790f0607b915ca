"""Partition-independent storage of FE fields: per input cell, the values of its DOFs (checkpoints of the FE
tier, the modal tier's saved basis), so a run can resume on any number of MPI ranks."""

from __future__ import annotations

import numpy as np


class CellLayout:
    """Partition-independent storage of a FE Function's local array: per input cell, the values of
    its DOFs. ``gather`` collects the owned cells on rank 0 (n_cells_global x DOFs per cell);
    ``scatter`` fills a local array (owned + ghost DOFs) from that table."""

    def __init__(self, space):
        msh = space.mesh
        comm = msh.comm
        tdim = msh.topology.dim
        imap = msh.topology.index_map(tdim)
        self.comm = comm
        self.n_owned = imap.size_local
        n_local = imap.size_local + imap.num_ghosts
        self.n_global = imap.size_global
        self.original = np.asarray(msh.topology.original_cell_index, dtype=np.int64)[:n_local]
        dofmap = space.dofmap
        bs = dofmap.bs
        cells = np.asarray(dofmap.list.array, dtype=np.int64).reshape(n_local, -1)
        self.dofs = (cells[:, :, None] * bs + np.arange(bs)).reshape(n_local, -1)
        index_map = dofmap.index_map
        self.local_size = (index_map.size_local + index_map.num_ghosts) * dofmap.index_map_bs

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        own = slice(0, self.n_owned)
        parts = self.comm.gather((self.original[own], values[self.dofs[own]]), root=0)
        if self.comm.rank != 0:
            return None
        table = np.zeros((self.n_global, self.dofs.shape[1]))
        for index, rows in parts:
            table[index] = rows
        return table

    def scatter(self, table: np.ndarray) -> np.ndarray:
        if table.shape != (self.n_global, self.dofs.shape[1]):
            raise ValueError(f"checkpoint field has shape {table.shape}, the mesh needs "
                             f"{(self.n_global, self.dofs.shape[1])}")
        out = np.zeros(self.local_size)
        out[self.dofs] = table[self.original]
        return out
