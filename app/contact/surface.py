"""Surface (facet) contacts in the modal tier: a facet group as interface nodes with lumped areas.

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

PLANE, SPHERE = 0, 1


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


@dataclass
class SurfaceContactSpec:
    """One frictionless surface contact of the modal tier, in the kernel's terms."""

    nodes: SurfaceNodes
    body: int                           # index of the rigid body
    body_reference_m: np.ndarray        # (gdim,) the body's reference position (its start)
    shape: str                          # "plane" or "sphere"
    normal: np.ndarray | None           # plane: outward unit normal (towards the FE body); sphere: pole or None
    radius_m: float                     # sphere radius (plane: unused)
    stiffness_Pa_per_m: float
    damping_Pa_s_per_m: float
    offset_m: np.ndarray | None = None  # obstacle point relative to the body's reference point


def kernel_surface_arrays(specs: list[SurfaceContactSpec], interface: list[int], gdim: int) -> dict:
    """The kernel's ``sn_*`` / ``sc_*`` arrays; appends the nodes' DOFs to ``interface`` (global DOF
    list, the Craig-Bampton interface order) and maps them to its coordinates.

    The reference relative position of a node is formed here once, in float64: x - (p_ref + offset)
    for a plane or a sphere without pole, x - (p_ref + offset + R pole) for a sphere with a pole
    (the kernel then forms the gap without cancellation, as the FE tier)."""
    n_nodes = sum(spec.nodes.size for spec in specs)
    out = {"sn_contact": np.zeros(n_nodes, np.int64), "sn_coord": np.full((n_nodes, gdim), -1, np.int64),
           "sn_rel": np.zeros((n_nodes, gdim)), "sn_area": np.zeros(n_nodes),
           "sc_body": np.zeros(len(specs), np.int64), "sc_kind": np.zeros(len(specs), np.int64),
           "sc_normal": np.zeros((len(specs), gdim)), "sc_radius": np.zeros(len(specs)),
           "sc_k": np.zeros(len(specs)), "sc_c": np.zeros(len(specs)), "sc_ref": np.zeros((len(specs), gdim))}
    position = {d: i for i, d in enumerate(interface)}
    row = 0
    for c, spec in enumerate(specs):
        ref = np.asarray(spec.body_reference_m, dtype=float)
        offset = np.zeros(gdim) if spec.offset_m is None else np.asarray(spec.offset_m, dtype=float)
        point = ref + offset
        pole = np.zeros(gdim)
        if spec.shape == "plane":
            out["sc_kind"][c] = PLANE
            out["sc_normal"][c] = spec.normal
        else:
            out["sc_kind"][c] = SPHERE
            if spec.normal is not None:
                pole = np.asarray(spec.normal, dtype=float)
                out["sc_normal"][c] = pole
                point = point + spec.radius_m * pole
        out["sc_body"][c], out["sc_radius"][c] = spec.body, spec.radius_m
        out["sc_k"][c], out["sc_c"][c], out["sc_ref"][c] = spec.stiffness_Pa_per_m, spec.damping_Pa_s_per_m, ref
        for i in range(spec.nodes.size):
            out["sn_contact"][row] = c
            out["sn_rel"][row] = spec.nodes.coordinates_m[i] - point
            out["sn_area"][row] = spec.nodes.area_m2[i]
            for k in range(gdim):
                dof = int(spec.nodes.global_dofs[i, k])
                if dof < 0:
                    continue
                if dof not in position:
                    position[dof] = len(interface)
                    interface.append(dof)
                out["sn_coord"][row, k] = position[dof]
            row += 1
    return out


def empty_surface_arrays(gdim: int) -> dict:
    return kernel_surface_arrays([], [], gdim)


SURFACE_KEYS = ("sn_contact", "sn_coord", "sn_rel", "sn_area", "sc_body", "sc_kind", "sc_normal", "sc_radius",
                "sc_k", "sc_c", "sc_ref")
