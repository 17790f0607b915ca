"""The one place for dolfinx-version differences (this code targets dolfinx 0.5.2 on Debian)."""

from __future__ import annotations

import dolfinx
import ufl
from dolfinx import fem
from dolfinx.io import gmshio

DOLFINX_VERSION = dolfinx.__version__


def model_to_mesh(model, comm, rank: int, gdim: int):
    """gmsh model -> (mesh, cell_tags, facet_tags); renamed ``dolfinx.io.gmsh`` in 0.10."""
    return gmshio.model_to_mesh(model, comm, rank, gdim=gdim)


def mixed_space(mesh, degree: int):
    """Vector Lagrange displacement x scalar Lagrange potential on one mesh."""
    cell = mesh.ufl_cell()
    element = ufl.MixedElement([ufl.VectorElement("Lagrange", cell, degree),
                                ufl.FiniteElement("Lagrange", cell, degree)])
    return fem.FunctionSpace(mesh, element)


def vector_space(mesh, family: str, degree: int):
    return fem.VectorFunctionSpace(mesh, (family, degree))


def scalar_space(mesh, family: str, degree: int):
    return fem.FunctionSpace(mesh, (family, degree))
