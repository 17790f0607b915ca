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


class PointSet:
    """Many physical points evaluated at once (collective, results on every rank): each point is evaluated by
    the lowest rank that owns a cell containing it. A point outside the mesh (within round-off of a faceted
    surface) takes the cell of the nearest owned vertex's cells that contains it best: ``missing`` lists the
    points no rank could place (the caller refuses them)."""

    def __init__(self, mesh, points: np.ndarray):
        comm = mesh.comm
        self.mesh = mesh
        pts = np.zeros((points.shape[0], 3))
        pts[:, : points.shape[1]] = points
        self.points = pts
        n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        links = colliding_cells(mesh, pts)
        cells = np.full(pts.shape[0], -1, dtype=np.int32)
        for i in range(pts.shape[0]):
            owned = [c for c in links.links(i) if c < n_owned]
            if owned:
                cells[i] = owned[0]
        rank = np.where(cells >= 0, comm.rank, comm.size).astype(np.int64)
        owner = rank
        if comm.size > 1:      # elementwise: the pickling allreduce's MIN compares whole arrays (and raises)
            owner = np.empty_like(rank)
            comm.Allreduce(rank, owner, op=MPI.MIN)
        self.mine = np.nonzero(owner == comm.rank)[0]
        self.cells = cells[self.mine]
        self.missing = np.nonzero(owner == comm.size)[0]

    def __call__(self, function) -> np.ndarray:
        """Values of ``function`` at every point, (n_points, value size), on every rank (0 at missing points)."""
        size = int(np.prod(function.ufl_shape)) if function.ufl_shape else 1
        out = np.zeros((self.points.shape[0], size))
        if self.mine.size:
            out[self.mine] = np.asarray(function.eval(self.points[self.mine], self.cells)).reshape(-1, size)
        comm = self.mesh.comm
        return comm.allreduce(out, op=MPI.SUM) if comm.size > 1 else out
