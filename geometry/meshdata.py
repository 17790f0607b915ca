"""Tagged dolfinx mesh with the physical-group names of its cells and facets."""

from __future__ import annotations

from dataclasses import dataclass, field

import gmsh
from mpi4py import MPI

from app.compat import model_to_mesh


@dataclass
class MeshData:
    mesh: object
    cell_tags: object
    facet_tags: object
    cell_names: dict[str, int] = field(default_factory=dict)
    facet_names: dict[str, int] = field(default_factory=dict)


def physical_names(dim: int) -> dict[str, int]:
    """Names of the current gmsh model's physical groups of dimension ``dim``."""
    names = {}
    for d, tag in gmsh.model.getPhysicalGroups(dim):
        name = gmsh.model.getPhysicalName(d, tag)
        names[name or str(tag)] = tag
    return names


def from_gmsh_model(comm: MPI.Comm, gdim: int, root: int = 0) -> MeshData:
    """Distribute the gmsh model held on ``root`` into a dolfinx mesh with tags and names."""
    names = None
    if comm.rank == root:
        tdim = gmsh.model.getDimension()
        names = (physical_names(tdim), physical_names(tdim - 1))
    names = comm.bcast(names, root=root)
    mesh, cell_tags, facet_tags = model_to_mesh(gmsh.model, comm, root, gdim=gdim)
    return MeshData(mesh, cell_tags, facet_tags, names[0], names[1])


_GMSH_STARTED = False


class GmshSession:
    """gmsh initialised on the root rank only, quiet, finalised on exit."""

    def __init__(self, comm: MPI.Comm, name: str, root: int = 0):
        self.comm, self.name, self.root = comm, name, root

    def __enter__(self):
        if self.comm.rank == self.root:
            global _GMSH_STARTED
            if not _GMSH_STARTED:
                gmsh.initialize()
                _GMSH_STARTED = True
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add(self.name)
        return self

    def __exit__(self, *exc):
        if self.comm.rank == self.root:
            gmsh.model.remove()
        return False
