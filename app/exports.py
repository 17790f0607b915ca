"""Exports: objects with ``write(...)``; solvers never open files.

Field files for ParaView are XDMF 3 written here (not by dolfinx's XDMFFile): the XML is ours and
the heavy data goes to HDF5 through h5py on rank 0. Every grid carries the displacement [m] (3
components, so Warp By Vector works in 2D too), the electric potential [V] at the same vertices
and the region tag of each cell, so one can warp by displacement and colour by potential on one
grid. Values are the fields interpolated to P1 (one per mesh vertex), gathered from the ranks in
the mesh's input node and cell order: a file has the same layout on any number of ranks.

A file is never left half-written: HDF5 data goes to a temporary name that is renamed into place,
and the XML is replaced atomically (write a temporary file, rename) after the data it names exists.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from dolfinx import fem

from app.compat import cell_geometry_nodes, scalar_space, vector_space
from app.files import replace_file, write_h5_atomic

# dolfinx cell name -> (XDMF topology type, vertices, vertex permutation dolfinx -> XDMF/VTK order)
_XDMF_CELLS = {
    "triangle": ("Triangle", 3, None),
    "tetrahedron": ("Tetrahedron", 4, None),
    "quadrilateral": ("Quadrilateral", 4, [0, 1, 3, 2]),
    "hexahedron": ("Hexahedron", 8, [0, 1, 3, 2, 4, 5, 7, 6]),
}


FE_GRID = "fe_body"      # name of the FE mesh's grid in every field file


class VertexFields:
    """Displacement [m] and potential [V] of a full u-phi vector at the mesh vertices, gathered on
    rank 0; and the mesh itself (vertex coordinates padded to 3, cells, region tag per cell) in the
    mesh's input order. ``sample(x)`` is collective and returns ``(u (N, 3), phi (N,))`` on rank 0,
    None elsewhere."""

    def __init__(self, model):
        mesh = model.mesh
        self.model = model
        self.comm = comm = mesh.comm
        tdim = mesh.topology.dim
        self.gdim = gdim = mesh.geometry.dim
        cell_name = mesh.topology.cell_type.name
        if cell_name not in _XDMF_CELLS or mesh.geometry.cmap.degree > 2:
            raise NotImplementedError(f"field export of {cell_name} meshes of geometry degree "
                                      f"{mesh.geometry.cmap.degree}")
        self.topology_type, nodes_per_cell, permutation = _XDMF_CELLS[cell_name]
        n_owned = mesh.topology.index_map(tdim).size_local
        geometry = mesh.geometry
        # a curved (quadratic) cell is written as the straight cell of its vertices, its first nodes
        cell_nodes = np.asarray(cell_geometry_nodes(mesh), dtype=np.int64)[:n_owned, :nodes_per_cell]
        # a Fourier model's amplitudes (U_r, U_theta, U_z) on the (r, z) grid go out as (U_r, U_z, U_theta): Warp
        # By Vector then moves the section as the mode does at theta = 0, the hoop amplitude out of its plane
        self.n_u = model.W.sub(0).num_sub_spaces
        self._u_order = [0, 2, 1] if model.kind == "fourier" else list(range(self.n_u))
        self.V1 = vector_space(mesh, "Lagrange", 1, dim=self.n_u)
        self.S1 = scalar_space(mesh, "Lagrange", 1)
        self.u1 = fem.Function(self.V1)
        self.phi1 = fem.Function(self.S1)
        self._phi_space, phi_map = model.W.sub(1).collapse()
        self._phi_map = np.asarray(phi_map)
        self._phi = fem.Function(self._phi_space)
        # P1 DOFs and geometry nodes share the reference vertex order of a cell (affine mesh)
        nodes = np.unique(cell_nodes)
        self._u_dofs = self._node_dofs(self.V1, cell_nodes, n_owned, geometry.x.shape[0])[nodes]
        self._phi_dofs = self._node_dofs(self.S1, cell_nodes, n_owned, geometry.x.shape[0])[nodes]
        coords = self.S1.tabulate_dof_coordinates()[self._phi_dofs]
        if not np.allclose(coords, geometry.x[nodes], rtol=0, atol=1e-12 * max(1.0, np.abs(geometry.x).max())):
            raise RuntimeError("P1 DOFs do not coincide with the mesh vertices")
        inputs = np.asarray(geometry.input_global_indices, dtype=np.int64)
        tags = np.zeros(n_owned + mesh.topology.index_map(tdim).num_ghosts, dtype=np.int32)
        cell_tags = model.mesh_data.cell_tags
        tags[np.asarray(cell_tags.indices)] = np.asarray(cell_tags.values)
        original = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:n_owned]
        parts = comm.gather((inputs[nodes], geometry.x[nodes], original, inputs[cell_nodes], tags[:n_owned]), root=0)
        self.mesh_arrays = None
        if comm.rank == 0:
            all_inputs = np.unique(np.concatenate([p[0] for p in parts]))
            self.n_nodes = all_inputs.size
            self._places = [np.searchsorted(all_inputs, p[0]) for p in parts]
            x = np.zeros((self.n_nodes, 3))
            for place, p in zip(self._places, parts):
                x[place, :gdim] = p[1][:, :gdim]
            n_cells = sum(p[2].size for p in parts)
            cells = np.zeros((n_cells, cell_nodes.shape[1]), dtype=np.int64)
            region = np.zeros(n_cells, dtype=np.int32)
            for p in parts:
                cells[p[2]] = np.searchsorted(all_inputs, p[3])
                region[p[2]] = p[4]
            if permutation is not None:
                cells = cells[:, permutation]
            self.mesh_arrays = {"geometry": x, "topology": cells, "region": region}
            self.n_cells = n_cells

    @staticmethod
    def _node_dofs(space, cell_nodes, n_owned, n_nodes) -> np.ndarray:
        dofs = np.asarray(space.dofmap.list.array, dtype=np.int64).reshape(-1, cell_nodes.shape[1])[:n_owned]
        out = np.full(n_nodes, -1, dtype=np.int64)
        out[cell_nodes.ravel()] = dofs.ravel()
        return out

    def sample_scalar(self, function) -> np.ndarray | None:
        """A scalar field (any dolfinx Function or Expression of one value on this mesh, e.g. the contact
        pressure [Pa]) interpolated to P1 at the vertices, gathered on rank 0 in the mesh's input order
        (None elsewhere). Collective."""
        target = fem.Function(self.S1)
        target.interpolate(function)
        target.x.scatter_forward()
        parts = self.comm.gather(target.x.array[self._phi_dofs], root=0)
        if self.comm.rank != 0:
            return None
        out = np.zeros(self.n_nodes)
        for place, part in zip(self._places, parts):
            out[place] = part
        return out

    def sample(self, x) -> tuple[np.ndarray, np.ndarray] | None:
        model = self.model
        self.u1.interpolate(model.displacement(x))
        self.u1.x.scatter_forward()
        n_owned = self._phi_space.dofmap.index_map.size_local * self._phi_space.dofmap.index_map_bs
        self._phi.x.array[:n_owned] = x.array_r[self._phi_map[:n_owned]]
        self._phi.x.scatter_forward()
        self.phi1.interpolate(self._phi)
        self.phi1.x.scatter_forward()
        u_local = self.u1.x.array.reshape(-1, self.n_u)[self._u_dofs][:, self._u_order]
        phi_local = self.phi1.x.array[self._phi_dofs]
        parts = self.comm.gather((u_local, phi_local), root=0)
        if self.comm.rank != 0:
            return None
        u = np.zeros((self.n_nodes, 3))
        phi = np.zeros(self.n_nodes)
        for place, (u_part, phi_part) in zip(self._places, parts):
            u[place, :self.n_u] = u_part
            phi[place] = phi_part
        return u, phi


# ------------------------------------------------------------------------- XDMF building blocks
def data_item(parent, source: str, shape, number: str = "Float", precision: int = 8) -> ET.Element:
    """An HDF5 (``file.h5:/path``) or inline (values as text) DataItem."""
    fmt = "HDF" if ":/" in source else "XML"
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(str(int(n)) for n in shape), NumberType=number,
                         Precision=str(precision), Format=fmt)
    item.text = source
    return item


def mesh_grid(name: str, vertex: VertexFields, mesh_h5: str, fields_at: str, scalars=()) -> ET.Element:
    """A uniform grid on the FE mesh with region tags (from ``mesh_h5``), displacement and potential
    (``<fields_at>/displacement``, ``<fields_at>/potential``, e.g. ``fields_at = "step.h5:"``) and the
    vertex scalars named in ``scalars`` (``<fields_at>/<name>``, e.g. ``contact_pressure_Pa``)."""
    grid = ET.Element("Grid", Name=name, GridType="Uniform")
    cells = vertex.mesh_arrays["topology"]
    topo = ET.SubElement(grid, "Topology", TopologyType=vertex.topology_type, NumberOfElements=str(cells.shape[0]),
                         NodesPerElement=str(cells.shape[1]))
    data_item(topo, f"{mesh_h5}:/mesh/topology", cells.shape, "Int")
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    data_item(geo, f"{mesh_h5}:/mesh/geometry", (vertex.n_nodes, 3))
    for attr_name, kind, center, source, shape, number in (
            ("displacement", "Vector", "Node", f"{fields_at}/displacement", (vertex.n_nodes, 3), "Float"),
            ("potential", "Scalar", "Node", f"{fields_at}/potential", (vertex.n_nodes,), "Float"),
            ("region", "Scalar", "Cell", f"{mesh_h5}:/mesh/region", (vertex.n_cells,), "Int"),
            *((scalar, "Scalar", "Node", f"{fields_at}/{scalar}", (vertex.n_nodes,), "Float") for scalar in scalars)):
        attr = ET.SubElement(grid, "Attribute", Name=attr_name, AttributeType=kind, Center=center)
        data_item(attr, source, shape, number, 8 if number == "Float" else 4)
    return grid


def point_grid(name: str, position: np.ndarray, displacement: np.ndarray) -> ET.Element:
    """A one-vertex grid (a rigid body) at ``position`` [m] with its displacement [m] (inline)."""
    grid = ET.Element("Grid", Name=name, GridType="Uniform")
    topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements="1", NodesPerElement="1")
    data_item(topo, "0", (1, 1), "Int", 4)
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    data_item(geo, " ".join(repr(float(v)) for v in _pad3(position)), (1, 3))
    attr = ET.SubElement(grid, "Attribute", Name="displacement", AttributeType="Vector", Center="Node")
    data_item(attr, " ".join(repr(float(v)) for v in _pad3(displacement)), (1, 3))
    return grid


def _pad3(v) -> np.ndarray:
    out = np.zeros(3)
    v = np.asarray(v, dtype=float).ravel()[:3]
    out[:v.size] = v
    return out


def xdmf_document(steps: list[ET.Element | bytes], name: str) -> bytes:
    """An XDMF 3 document: one temporal collection ``name`` holding ``steps`` (elements, or their
    bytes from :func:`step_bytes`: a long series serialises each step once, not at every output)."""
    head = (f'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n<Xdmf Version="3.0">\n <Domain>\n'
            f'  <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n').encode()
    body = b"".join(s if isinstance(s, bytes) else step_bytes(s) for s in steps)
    return head + body + b"  </Grid>\n </Domain>\n</Xdmf>\n"


def step_bytes(step: ET.Element) -> bytes:
    """One time step's element, indented for its place in :func:`xdmf_document`."""
    ET.indent(step, space=" ", level=3)
    return ("   " + ET.tostring(step, encoding="unicode") + "\n").encode()


def write_mesh_h5(path: Path, vertex: VertexFields) -> None:
    arrays = vertex.mesh_arrays
    write_h5_atomic(path, {f"mesh/{k}": v for k, v in arrays.items()},
                    {"mesh/geometry": {"units": "m"}, "mesh/region": {"meaning": "cell group tag of the mesh"}})


class _VertexSeriesExport:
    """Frames of full u-phi vectors sampled at the vertices, one grid each (displacement, potential,
    region), written by ``close()``: HDF5 first, then the XML, each through a temporary file and a
    rename. Subclasses name the frames and their time values."""

    group = "frame"

    def __init__(self, path: Path, model):
        self.path = Path(path)
        self.h5_path = self.path.with_suffix(".h5")
        self.vertex = VertexFields(model)
        self.frames: list[tuple[float, np.ndarray, np.ndarray]] = []

    def write(self, vector, value: float) -> None:
        sampled = self.vertex.sample(vector)
        if sampled is not None:
            self.frames.append((float(value), *sampled))

    def _name(self, k: int, value: float) -> str:
        raise NotImplementedError

    def _decorate(self, step: ET.Element, value: float) -> None:
        """Extra attributes of a frame's grid (none by default)."""

    def _attrs(self, value: float) -> dict:
        return {}

    def close(self) -> list[str]:
        """Write the files (rank 0); returns their names."""
        names = [self.path.name, self.h5_path.name]
        if self.vertex.comm.rank != 0:
            return names
        datasets = {f"mesh/{k}": v for k, v in self.vertex.mesh_arrays.items()}
        steps, attrs = [], {}
        for k, (value, u, phi) in enumerate(self.frames):
            group = self._group(k)
            datasets[f"{group}/displacement"] = u
            datasets[f"{group}/potential"] = phi
            attrs[f"{group}/displacement"] = self._attrs(value)
            step = mesh_grid(self._name(k, value), self.vertex, self.h5_path.name, f"{self.h5_path.name}:/{group}")
            step.insert(0, ET.Element("Time", Value=repr(value)))
            self._decorate(step, value)
            steps.append(step)
        write_h5_atomic(self.h5_path, datasets, attrs)
        replace_file(self.path, xdmf_document(steps, self.path.stem))
        return names

    def _group(self, k: int) -> str:
        return f"{self.group}_{k}"


class ModeShapeExport(_VertexSeriesExport):
    """Mode shapes of one electrical state as XDMF for ParaView: one grid per mode with the
    displacement (mass-normalised shape [1/sqrt(kg)]), the potential and the region tags. The
    'time' of a mode is its frequency [Hz] and its grid is named ``mode <k>: <f> Hz``, so
    ParaView's time control steps through the modes and shows their frequencies.

    ``write(vector, frequency_Hz)`` takes a full u-phi vector; ``close()`` writes the files."""

    def _group(self, k: int) -> str:
        return f"mode_{k + 1}"

    def _name(self, k: int, value: float) -> str:
        return f"mode {k + 1}: {value:.2f} Hz"

    def _decorate(self, step: ET.Element, value: float) -> None:
        frequency = ET.SubElement(step, "Attribute", Name="frequency_Hz", AttributeType="Scalar", Center="Grid")
        data_item(frequency, repr(value), (1,))

    def _attrs(self, value: float) -> dict:
        return {"frequency_Hz": value, "units": "1/sqrt(kg) (mass-normalised)"}


class WaveExport(_VertexSeriesExport):
    """A steady harmonic response over one period as an XDMF time series for ParaView (the
    travelling wave of a motor stator): ``write(vector, t_s)`` takes the full u-phi vector of the
    field at time t [s] (displacement [m], potential [V])."""

    def _name(self, k: int, value: float) -> str:
        return f"t = {value * 1e6:.3f} us"

    def _attrs(self, value: float) -> dict:
        return {"units": "m"}
