"""Import of gmsh ``.msh`` files with physical names, and meshio export."""

from __future__ import annotations

from pathlib import Path

import gmsh
from mpi4py import MPI

from app.compat import cell_geometry_nodes
from app.errors import CaseError
from geometry.meshdata import GmshSession, MeshData, from_gmsh_model


def read_msh(comm: MPI.Comm, path: Path, gdim: int, file: str | None = None) -> MeshData:
    """Read a .msh file on rank 0 and distribute it (dolfinx's own read_from_msh is broken on
    Debian's 0.5.2). Unreadable files raise CaseError naming ``geometry.mesh_file``."""
    ok = None
    with GmshSession(comm, "file"):
        if comm.rank == 0:
            try:
                if not path.is_file():
                    raise OSError("no such file")
                with open(path, "rb") as f:     # else gmsh parses it as a script, its message depends on its state
                    if not f.read(64).lstrip().startswith(b"$"):
                        raise OSError("not a gmsh .msh file (it does not start with $MeshFormat)")
                gmsh.merge(str(path))
                tdim = gmsh.model.getDimension()
                if tdim < gdim or not gmsh.model.getPhysicalGroups(tdim):
                    raise OSError(f"no {gdim}D physical groups (cells need a physical group)")
                ok = ""
            except Exception as exc:  # gmsh raises bare Exception on parse errors
                ok = "".join(c for c in str(exc) if c.isprintable()) or type(exc).__name__
        ok = comm.bcast(ok, root=0)
        if ok:
            raise CaseError(file, "geometry.mesh_file", f"cannot read mesh {str(path)!r}: {ok}")
        return from_gmsh_model(comm, gdim)


def export_meshio(mesh_data: MeshData, path: Path) -> None:
    """Write the (serial) mesh with cell tags to any meshio format (by file suffix)."""
    import meshio
    import numpy as np

    mesh = mesh_data.mesh
    tdim = mesh.topology.dim
    cells = cell_geometry_nodes(mesh)
    cell_type = {2: "triangle", 3: "tetra"}[tdim]
    if cells.shape[1] == 6:
        cell_type += "6"
    elif cells.shape[1] == 10:
        cell_type += "10"
    tags = np.zeros(cells.shape[0], dtype=np.int32)
    tags[mesh_data.cell_tags.indices] = mesh_data.cell_tags.values
    points = mesh.geometry.x[:, : mesh.geometry.dim]
    meshio.write(str(path), meshio.Mesh(points, [(cell_type, cells)], cell_data={"region": [tags]}))
