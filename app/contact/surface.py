"""A facet group as nodes with lumped areas: the sites of a surface contact sampled at its nodes.

The FE tier integrates the penalty pressure over the facets at quadrature points. The modal tier
keeps the facet group's nodes as Craig-Bampton interface coordinates (every displacement DOF of
every node, so the contact sees the FE surface exactly) and integrates the pressure by nodal
quadrature: node i carries a lumped area A_i [m^2, times the volume weight: 2 pi r axisymmetric,
the thickness in plane strain] and pushes with A_i p(g_i) along the obstacle's normal at the node.

The lumped areas are the row sums of the facet mass matrix m_ij = int N_i N_j w ds, i.e. A_i =
int N_i w ds, the consistent nodal force of a uniform pressure, exact for linear facets (P1, and
the P2 interval: L/6, 2L/3, L/6). On quadratic triangles and 8-node quadrilaterals those row sums
are zero or negative at the vertices (int N_vertex ds = 0 on a P2 triangle): a vertex that
penetrates would then feel no (or an attracting) force, and a surface that touches at a corner
would pass through. Then the areas are the HRZ lumping (Hinton, Rock & Zienkiewicz 1976): the
diagonal m_ii scaled so the areas sum to the group's area, A_i = m_ii int w ds / sum_j m_jj, which
is positive for every Lagrange element and, for affine facets of one kind and a constant weight,
equals the per-facet HRZ diagonal (m_ii^f / sum_j m_jj^f is then the same ratio on every facet).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix, assemble_vector
from mpi4py import MPI
from petsc4py import PETSc


@dataclass
class SurfaceNodes:
    """The nodes of a facet group, the same arrays on every rank (sorted by coordinates, so the
    order does not depend on the partition)."""

    coordinates_m: np.ndarray          # (n, gdim) reference coordinates
    global_dofs: np.ndarray            # (n, gdim) global displacement DOF per axis, -1 where held
    area_m2: np.ndarray                # (n,) lumped area (volume-weighted)
    lumping: str                       # "row sum" or "HRZ"

    @property
    def size(self) -> int:
        return int(self.area_m2.size)


def surface_nodes(space, displacement, facet_tags, tag: int, weight, held_local: np.ndarray) -> SurfaceNodes:
    """Nodes, global DOFs and lumped areas of facet group ``tag``.

    ``space``: the full function space (the u-phi mixed space, or a vector space); ``displacement``:
    its displacement (vector) subspace (``space.sub(0)``, or ``space`` itself); ``weight``: the
    volume weight (UFL expression or number); ``held_local``: local DOFs of ``space`` held at zero
    (supports): those components are not coordinates (-1)."""
    mesh = space.mesh
    comm = mesh.comm
    gdim = mesh.geometry.dim
    fdim = mesh.topology.dim - 1
    facets = facet_tags.indices[facet_tags.values == tag]
    imap = space.dofmap.index_map
    bs = space.dofmap.index_map_bs
    collapsed = [displacement.sub(k).collapse() for k in range(gdim)]
    scalar, _ = collapsed[0]
    # the component spaces share one scalar dofmap: node j of axis 0 is node j of every axis
    coords = scalar.tabulate_dof_coordinates()[:, :gdim]
    for V_k, _ in collapsed[1:]:
        if not np.array_equal(V_k.tabulate_dof_coordinates()[:, :gdim], coords):
            raise ValueError("displacement components with different node numberings")
    nodes = fem.locate_dofs_topological(scalar, fdim, facets)
    owned = nodes[nodes < scalar.dofmap.index_map.size_local]

    # facet mass matrix of the scalar space: row sums and diagonal
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)(tag)
    u, v = ufl.TrialFunction(scalar), ufl.TestFunction(scalar)
    row_sums = assemble_vector(fem.form(v * weight * ds))
    row_sums.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    matrix = assemble_matrix(fem.form(u * v * weight * ds))
    matrix.assemble()
    diagonal = matrix.getDiagonal()
    area = comm.allreduce(fem.assemble_scalar(fem.form(weight * ds)), op=MPI.SUM)
    rows = row_sums.array_r[owned]
    diag = diagonal.array_r[owned]
    positive = comm.allreduce(bool(np.all(rows > 0)), op=MPI.LAND)
    if positive:
        lumped, lumping = rows.copy(), "row sum"
    else:
        lumped, lumping = diag * area / comm.allreduce(float(diag.sum()), op=MPI.SUM), "HRZ"
    for vec in (row_sums, diagonal):
        vec.destroy()
    matrix.destroy()

    held = set(np.asarray(held_local).tolist())
    dofs = np.full((owned.size, gdim), -1, dtype=np.int64)
    for k, (_, parent) in enumerate(collapsed):
        local = np.asarray(parent)[owned]
        glob = imap.local_to_global((local // bs).astype(np.int32)) * bs + local % bs
        keep = np.array([d not in held for d in local.tolist()], dtype=bool)
        dofs[keep, k] = glob[keep]
    gathered = comm.allgather((coords[owned], dofs, lumped))
    x = np.concatenate([g[0] for g in gathered]).reshape(-1, gdim)
    # sort on rounded coordinates: the order must not hang on round-off of the mesh coordinates
    keys = np.round(x / max(np.abs(x).max(initial=0.0), 1e-30), 10)
    order = np.lexsort(keys.T[::-1])
    return SurfaceNodes(x[order], np.concatenate([g[1] for g in gathered]).reshape(-1, gdim)[order],
                        np.concatenate([g[2] for g in gathered])[order], lumping)
