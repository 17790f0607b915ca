"""Exports: objects with ``write(...)``; solvers never open files.

Field files for ParaView are XDMF 3 written here (not by dolfinx's XDMFFile): the XML is ours and
the heavy data goes to HDF5 through h5py on rank 0. Every grid carries the displacement [m] (3
components, so Warp By Vector works in 2D too), the electric potential [V] at the same vertices,
the region tag of each cell and one indicator cell array per named region (``region: <name>``,
:func:`region_indicators`), so one can warp by displacement and colour by potential on one
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
    None elsewhere. ``derived``: the derived fields (app.fe.derived.DERIVED_FIELDS) the writers add,
    from :meth:`sample_derived`."""

    def __init__(self, model, derived=()):
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
        self.derived = tuple(derived)
        self._evaluator = None
        self._scalar_target = None         # the P1 function sample_scalar interpolates into, made once
        self.region_names = {int(r.tag): r.name for r in model.regions}
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
            self._cell_orders = [p[2] for p in parts]
            from app.fe.derived import RegionAveraging

            self.averaging = RegionAveraging(cells, region, self.n_nodes,
                                             [r.tag for r in model.regions if r.e is not None])
            if permutation is not None:
                cells = cells[:, permutation]
            self.mesh_arrays = {"geometry": x, "topology": cells, "region": region}
            self.n_cells = n_cells

    def sample_derived(self, x) -> np.ndarray | None:
        """Strain, stress, E, D at the vertices of every cell, unaveraged (app.fe.derived.CellVertexEvaluator),
        gathered on rank 0 in the mesh's input cell order: (cells, vertices, 18); None elsewhere. Collective."""
        from app.fe.derived import CellVertexEvaluator

        if self._evaluator is None:
            self._evaluator = CellVertexEvaluator(self.model)
        parts = self.comm.gather(self._evaluator.evaluate(x), root=0)
        if self.comm.rank != 0:
            return None
        raw = np.zeros((self.n_cells,) + parts[0].shape[1:])
        for order, part in zip(self._cell_orders, parts):
            raw[order] = part
        return raw

    def derived_frame(self, x):
        """(derived vertex fields, peaks per region) of a full u-phi vector on rank 0, (None, None) elsewhere:
        app.fe.derived.node_fields and region_peaks of the region-wise averaged values. Collective."""
        from app.fe.derived import node_fields, region_peaks

        raw = self.sample_derived(x)
        if raw is None:
            return None, None
        pairs = self.averaging.average(raw)
        return (node_fields(self.averaging.at_vertices(pairs), self.derived),
                region_peaks(pairs, self.averaging.pair_region, self.model.regions))

    def vertex_average(self, raw: np.ndarray) -> np.ndarray:
        """One value per vertex (vertices, columns) of cell-vertex values (cells, vertices, columns), averaged
        region by region (app.fe.derived.RegionAveraging; rank 0)."""
        return self.averaging.at_vertices(self.averaging.average(raw))

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
        if self._scalar_target is None:
            self._scalar_target = fem.Function(self.S1)
        target = self._scalar_target
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


def mesh_grid(name: str, vertex: VertexFields, mesh_h5: str, fields_at: str, extra=(), frame: str = "") -> ET.Element:
    """A uniform grid on the FE mesh with region tags (from ``mesh_h5``), displacement and potential
    (``<fields_at>/displacement<frame>``, ``<fields_at>/potential<frame>``, e.g. ``fields_at = "modes.h5:/mode_1"``
    or, a transient frame's, ``fields_at = "frames_000064.h5:"``, ``frame = "/step_000070"``), and the vertex fields
    ``extra``: (name, components) each at ``<fields_at>/<name><frame>`` (derived fields, the contact pressure)."""
    grid = ET.Element("Grid", Name=name, GridType="Uniform")
    cells = vertex.mesh_arrays["topology"]
    topo = ET.SubElement(grid, "Topology", TopologyType=vertex.topology_type, NumberOfElements=str(cells.shape[0]),
                         NodesPerElement=str(cells.shape[1]))
    data_item(topo, f"{mesh_h5}:/mesh/topology", cells.shape, "Int")
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    data_item(geo, f"{mesh_h5}:/mesh/geometry", (vertex.n_nodes, 3))
    for attr_name, kind, center, source, shape, number in (
            ("displacement", "Vector", "Node", f"{fields_at}/displacement{frame}", (vertex.n_nodes, 3), "Float"),
            ("potential", "Scalar", "Node", f"{fields_at}/potential{frame}", (vertex.n_nodes,), "Float"),
            ("region", "Scalar", "Cell", f"{mesh_h5}:/mesh/region", (vertex.n_cells,), "Int")):
        attr = ET.SubElement(grid, "Attribute", Name=attr_name, AttributeType=kind, Center=center)
        data_item(attr, source, shape, number, 8 if number == "Float" else 4)
    for tag, name in sorted(getattr(vertex, "region_names", {}).items()):
        attr = ET.SubElement(grid, "Attribute", Name=region_indicator_name(name), AttributeType="Scalar", Center="Cell")
        data_item(attr, f"{mesh_h5}:/{region_indicator_path(tag)}", (vertex.n_cells,), "Int", 1)
    for attr_name, components in extra:
        kind = {1: "Scalar", 3: "Vector"}.get(components, "Matrix")
        attr = ET.SubElement(grid, "Attribute", Name=attr_name, AttributeType=kind, Center="Node")
        shape = (vertex.n_nodes,) if components == 1 else (vertex.n_nodes, components)
        data_item(attr, f"{fields_at}/{attr_name}{frame}", shape)
    return grid


REGION_INDICATOR_PREFIX = "region: "


def region_indicator_name(name: str) -> str:
    """The cell array that marks region ``name`` (1 in its cells, 0 elsewhere), e.g. ``region: horn``."""
    return REGION_INDICATOR_PREFIX + name


def region_indicator_path(tag: int) -> str:
    return f"mesh/in_region_{int(tag)}"


def region_indicators(vertex) -> dict[str, np.ndarray]:
    """The region indicator cell arrays of a mesh (rank 0): {HDF5 path: int8 1 in the region's cells, 0 elsewhere},
    one per named region. Why: ParaView's XDMF readers show neither the Domain's Information nor field data
    meshio can read (a Grid-centred Attribute breaks meshio's reader), and XDMF Sets come out unwarped; a cell
    array per region carries the name into ParaView's array list (Threshold on ``region: horn`` between 1 and 1
    extracts the horn) and into meshio's cell_data. Written once in the mesh's HDF5 file (1 byte per cell and
    region), named by every frame's grid."""
    region = vertex.mesh_arrays["region"]
    return {region_indicator_path(tag): (region == tag).astype(np.int8)
            for tag in sorted(getattr(vertex, "region_names", {}))}


def mesh_datasets(vertex) -> dict[str, np.ndarray]:
    """The datasets of a field file's mesh (rank 0): ``mesh/geometry``, ``mesh/topology``, ``mesh/region`` and the
    region indicators (:func:`region_indicators`)."""
    return {**{f"mesh/{k}": v for k, v in vertex.mesh_arrays.items()}, **region_indicators(vertex)}


def region_information(region_names: dict[int, str]) -> ET.Element:
    """The region tag -> name table as an XDMF Information element of the Domain (``Value`` "1: horn; 2: back";
    meshio reads past it, and ``mesh/region`` in the HDF5 file carries the same table as attribute ``names``)."""
    return ET.Element("Information", Name="region_names", Value=region_names_text(region_names))


def region_names_text(region_names: dict[int, str]) -> str:
    return "; ".join(f"{tag}: {name}" for tag, name in sorted(region_names.items()))


def extra_fields(names: dict) -> list[tuple[str, int]]:
    """(name, components) of a frame's derived vertex fields (name -> (n,) or (n, k) array)."""
    return [(name, 1 if np.ndim(values) == 1 else np.shape(values)[1]) for name, values in names.items()]


def xdmf_document(steps: list[ET.Element | bytes], name: str, region_names: dict[int, str] | None = None) -> bytes:
    """An XDMF 3 document: one temporal collection ``name`` holding ``steps`` (elements, or their
    bytes from :func:`step_bytes`: a long series serialises each step once, not at every output),
    after the region names' Information element when ``region_names`` is given."""
    info = ""
    if region_names:
        info = "  " + ET.tostring(region_information(region_names), encoding="unicode") + "\n"
    head = (f'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n<Xdmf Version="3.0">\n <Domain>\n{info}'
            f'  <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n').encode()
    body = b"".join(s if isinstance(s, bytes) else step_bytes(s) for s in steps)
    return head + body + b"  </Grid>\n </Domain>\n</Xdmf>\n"


def step_bytes(step: ET.Element) -> bytes:
    """One time step's element, indented for its place in :func:`xdmf_document`."""
    ET.indent(step, space=" ", level=3)
    return ("   " + ET.tostring(step, encoding="unicode") + "\n").encode()


def write_mesh_h5(path: Path, vertex: VertexFields) -> None:
    write_h5_atomic(path, mesh_datasets(vertex), mesh_h5_attributes(vertex))


def mesh_h5_attributes(vertex: VertexFields) -> dict:
    region_names = getattr(vertex, "region_names", {})
    names = region_names_text(region_names)
    return {"mesh/geometry": {"units": "m"}, "mesh/region": {"meaning": "cell group tag of the mesh", "names": names},
            **{region_indicator_path(tag): {"meaning": f"1 in the cells of region {tag} ({name}), 0 elsewhere",
                                            "name": region_indicator_name(name)}
               for tag, name in region_names.items()}}


class _VertexSeriesExport:
    """Frames of full u-phi vectors sampled at the vertices, one grid each (displacement, potential,
    region), written by ``close()``: HDF5 first, then the XML, each through a temporary file and a
    rename. Subclasses name the frames and their time values."""

    group = "frame"

    def __init__(self, path: Path, model, derived=()):
        self.path = Path(path)
        self.h5_path = self.path.with_suffix(".h5")
        self.vertex = VertexFields(model, derived)
        self.frames: list[tuple[float, np.ndarray, np.ndarray, dict]] = []

    def write(self, vector, value: float) -> None:
        sampled = self.vertex.sample(vector)
        extra = self._derived(vector)
        if sampled is not None:
            self.frames.append((float(value), *sampled, extra))

    def _derived(self, vector) -> dict:
        """The frame's derived vertex fields (name -> array, rank 0), app.fe.derived. Collective."""

        if not self.vertex.derived:
            return {}
        fields, _ = self.vertex.derived_frame(vector)
        return fields or {}

    def _name(self, k: int, value: float) -> str:
        raise NotImplementedError

    def _decorate(self, step: ET.Element, k: int, value: float) -> None:
        """Extra attributes of frame k's grid (none by default)."""

    def _attrs(self, k: int, value: float) -> dict:
        return {}

    def close(self) -> list[str]:
        """Write the files (rank 0); returns their names."""
        names = [self.path.name, self.h5_path.name]
        if self.vertex.comm.rank != 0:
            return names
        datasets = mesh_datasets(self.vertex)
        steps, attrs = [], mesh_h5_attributes(self.vertex)
        for k, (value, u, phi, extra) in enumerate(self.frames):
            group = self._group(k)
            datasets[f"{group}/displacement"] = u
            datasets[f"{group}/potential"] = phi
            attrs[f"{group}/displacement"] = self._attrs(k, value)
            attrs[f"{group}/potential"] = {"units": "V"}
            for name, values in extra.items():
                datasets[f"{group}/{name}"] = values
            step = mesh_grid(self._name(k, value), self.vertex, self.h5_path.name, f"{self.h5_path.name}:/{group}",
                             extra_fields(extra))
            step.insert(0, ET.Element("Time", Value=repr(value)))
            self._decorate(step, k, value)
            steps.append(step)
        write_h5_atomic(self.h5_path, datasets, attrs)
        replace_file(self.path, xdmf_document(steps, self.path.stem, self.vertex.region_names))
        return names

    def _group(self, k: int) -> str:
        return f"{self.group}_{k}"


class ModeShapeExport(_VertexSeriesExport):
    """Mode shapes of one electrical state as XDMF for ParaView and meshio: one grid per mode with the
    displacement [m] and potential [V] of the shape scaled so its largest vertex displacement is
    ``amplitude_m`` (``output.mode_shape_amplitude_m``, default 1 mm: Warp By Vector at scale 1 shows it;
    the mass-normalised shape [1/sqrt(kg)] is the written one divided by ``shape_scale_m_sqrt_kg``, an
    Information of the grid and an attribute of ``mode_<k>/displacement`` in the HDF5 file), and the
    region tags. The 'time' of a mode is its frequency [Hz] and its grid is named ``mode <k>: <f> Hz``
    (modes numbered from 1, as in modes.csv and the summary), so ParaView's time control steps through the
    modes and shows their frequencies.

    ``write(vector, frequency_Hz)`` takes a full u-phi vector; ``close()`` writes the files."""

    def __init__(self, path: Path, model, amplitude_m: float = 1e-3, derived=()):
        super().__init__(path, model, derived)
        self.amplitude_m = float(amplitude_m)
        self.scales: list[float] = []

    def write(self, vector, value: float) -> None:
        sampled = self.vertex.sample(vector)
        extra = self._derived(vector)
        if sampled is not None:
            u, phi = sampled
            largest = float(np.linalg.norm(u, axis=1).max(initial=0.0))
            scale = self.amplitude_m / largest if largest > 0 else 1.0
            self.scales.append(scale)
            # the derived fields are linear in the shape: the same scale as the displacement
            self.frames.append((float(value), u * scale, phi * scale, {k: v * scale for k, v in extra.items()}))

    def _group(self, k: int) -> str:
        return f"mode_{k + 1}"

    def _name(self, k: int, value: float) -> str:
        return f"mode {k + 1}: {value:.2f} Hz"

    def _decorate(self, step: ET.Element, k: int, value: float) -> None:
        # Information, not a Grid-centred Attribute: meshio's TimeSeriesReader refuses any Attribute that is
        # neither Node- nor Cell-centred; the frequency is also the grid's time value and in its name
        for name, grid_value in (("frequency_Hz", value), ("shape_scale_m_sqrt_kg", self.scales[k])):
            ET.SubElement(step, "Information", Name=name, Value=repr(grid_value))

    def _attrs(self, k: int, value: float) -> dict:
        return {"frequency_Hz": value, "units": "m", "amplitude_m": self.amplitude_m,
                "shape_scale_m_sqrt_kg": self.scales[k],
                "meaning": "mass-normalised mode shape [1/sqrt(kg)] times shape_scale_m_sqrt_kg: its largest vertex "
                           "displacement is amplitude_m"}


class WaveExport(_VertexSeriesExport):
    """A steady harmonic response over one period as an XDMF time series for ParaView (the
    travelling wave of a motor stator): ``write(vector, t_s)`` takes the full u-phi vector of the
    field at time t [s] (displacement [m], potential [V])."""

    def _name(self, k: int, value: float) -> str:
        return f"t = {value * 1e6:.3f} us"

    def _attrs(self, k: int, value: float) -> dict:
        return {"units": "m"}


class HarmonicFieldExport(_VertexSeriesExport):
    """The steady harmonic response at one frequency as one XDMF grid (its 'time' the frequency [Hz]): the
    real parts of displacement [m] and potential [V] as ``displacement`` and ``potential`` (Warp By Vector
    shows phase 0), the imaginary parts as ``displacement_im`` and ``potential_im``, and the derived fields
    of :func:`app.fe.derived.harmonic_node_fields` (real and imaginary parts, maxima over the cycle).
    ``write_phasor(x_re, x_im, f)`` is collective and returns the peaks per region over the cycle
    (:func:`app.fe.derived.region_peaks`) on every rank."""

    def write_phasor(self, x_re, x_im, frequency_Hz: float) -> dict:
        from app.fe.derived import harmonic_node_fields, region_peaks

        vertex = self.vertex
        re, im = vertex.sample(x_re), vertex.sample(x_im)
        raw_re, raw_im = vertex.sample_derived(x_re), vertex.sample_derived(x_im)
        peaks = {}
        if vertex.comm.rank == 0:
            extra = {"displacement_im": im[0], "potential_im": im[1]}
            pairs_re, pairs_im = vertex.averaging.average(raw_re), vertex.averaging.average(raw_im)
            at = vertex.averaging.at_vertices
            extra.update(harmonic_node_fields(at(pairs_re), at(pairs_im), vertex.derived))
            self.frames.append((float(frequency_Hz), *re, extra))
            peaks = region_peaks(pairs_re, vertex.averaging.pair_region, vertex.model.regions, pairs_im)
        return vertex.comm.bcast(peaks, root=0)

    def _group(self, k: int) -> str:
        return "harmonic"

    def _name(self, k: int, value: float) -> str:
        return f"harmonic response at {value:.2f} Hz"

    def _attrs(self, k: int, value: float) -> dict:
        return {"frequency_Hz": value, "units": "m"}
