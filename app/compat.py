"""The one place for dolfinx-version differences (this code targets dolfinx 0.5.2 on Debian)."""

from __future__ import annotations

import ufl
from dolfinx import fem
from dolfinx.io import gmshio


def model_to_mesh(model, comm, rank: int, gdim: int):
    """gmsh model -> (mesh, cell_tags, facet_tags); renamed ``dolfinx.io.gmsh`` in 0.10."""
    return gmshio.model_to_mesh(model, comm, rank, gdim=gdim)


def mixed_space(mesh, degree: int, displacement_dim: int | None = None):
    """Vector Lagrange displacement (``displacement_dim`` components, default the mesh's geometric
    dimension) x scalar Lagrange potential on one mesh."""
    cell = mesh.ufl_cell()
    element = ufl.MixedElement([ufl.VectorElement("Lagrange", cell, degree, dim=displacement_dim),
                                ufl.FiniteElement("Lagrange", cell, degree)])
    return fem.FunctionSpace(mesh, element)


def vector_space(mesh, family: str, degree: int, dim: int | None = None):
    return fem.VectorFunctionSpace(mesh, (family, degree), dim=dim)


def scalar_space(mesh, family: str, degree: int):
    return fem.FunctionSpace(mesh, (family, degree))


def petsc_vector(function: fem.Function):
    """The PETSc Vec of a Function's values (owned + ghosts); ``Function.x.petsc_vec`` from 0.8."""
    return function.vector


def is_mixed(space) -> bool:
    """True for a mixed space (u-phi), False for a plain vector or scalar space; from 0.7 the
    elements are basix.ufl elements (``space.element.num_sub_elements`` / ``blocked``)."""
    element = space.ufl_element()
    return isinstance(element, ufl.MixedElement) and not isinstance(element, ufl.VectorElement)


def cell_geometry_nodes(mesh):
    """(n_cells, nodes per cell) geometry node indices of the local cells (owned first); the
    geometry dofmap is an AdjacencyList in 0.5-0.6 and a 2-D array from 0.7."""
    dofmap = mesh.geometry.dofmap
    return dofmap.array.reshape(-1, dofmap.offsets[1])


def cell_candidates(mesh, points):
    """Per point (n x 3), the local cells whose bounding box holds it, as an AdjacencyList
    (``geometry.bb_tree`` / ``compute_collisions_points`` from 0.7)."""
    from dolfinx import geometry

    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    return geometry.compute_collisions(tree, points)


def colliding_cells(mesh, points):
    """Per point (n x 3), the local cells that contain it (AdjacencyList)."""
    from dolfinx import geometry

    return geometry.compute_colliding_cells(mesh, cell_candidates(mesh, points), points)


def expression_at_points(ufl_expr, reference_points):
    """A compiled UFL expression evaluated at ``reference_points`` (n, tdim) of each cell."""
    return fem.Expression(ufl_expr, reference_points)


def evaluate_expression(expression, mesh, cells):
    """(len(cells), points x value size) values of an Expression; ``eval(mesh, cells)`` from 0.7."""
    import numpy as np

    return expression.eval(np.asarray(cells, dtype=np.int32))
