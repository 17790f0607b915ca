"""Evaluating a Function at a physical point on any MPI partition (result on every rank)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from app.compat import colliding_cells


class PointProbe:
    def __init__(self, mesh, point: np.ndarray):
        self.mesh = mesh
        self.point = np.zeros(3)
        self.point[: point.size] = point
        local = colliding_cells(mesh, self.point.reshape(1, 3)).links(0)
        n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        owned = [c for c in local if c < n_owned]
        # exactly one rank evaluates: the lowest rank that owns a colliding cell
        has = 1 if owned else 0
        rank = mesh.comm.rank if has else mesh.comm.size
        self.owner = mesh.comm.allreduce(rank, op=MPI.MIN)
        self.found = self.owner < mesh.comm.size
        self.cell = owned[0] if (owned and self.owner == mesh.comm.rank) else None

    def __call__(self, function) -> np.ndarray:
        """Values of ``function`` (any value shape, flattened) at the point, on all ranks."""
        value = None
        if self.cell is not None:
            cells = np.array([self.cell], dtype=np.int32)
            value = np.asarray(function.eval(self.point.reshape(1, 3), cells)).reshape(-1)
        return self.mesh.comm.bcast(value, root=self.owner)
