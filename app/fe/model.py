"""From a validated Case to a discrete piezoelectric FE model: mesh, mixed u-phi space, UFL forms,
electrode and support DOFs, probes. Mesh-dependent input errors (missing groups, conflicting
electrodes) raise CaseError naming the case key.

Non-piezoelectric regions are treated as grounded conductors: their potential DOFs are held at
0 V (metal parts of a Langevin transducer are the ground electrodes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from app.case.schema import Case
from app.case.validate import from_dict
from app.compat import mixed_space
from app.errors import CaseError
from forms import dynamics, piezo, voigt
from forms.kinematics import displacement_components, kinematics, volume_weight
from geometry.builders import BUILDERS
from geometry.meshdata import MeshData
from geometry.mshfile import read_msh

COMPONENTS = {
    "axisymmetric": {"r": 0, "x": 0, "z": 1},
    "plane_strain": {"x": 0, "z": 1},
    "3d": {"x": 0, "y": 1, "z": 2},
    "fourier": {"r": 0, "x": 0, "y": 1, "z": 2},   # amplitudes (U_r, U_theta, U_z): y is the hoop axis
}
# what a Fourier-harmonic model runs: its modes (a drive would need an electrode whose potential varies as
# cos n theta round the circumference; transient contact breaks the single order)
FOURIER_ANALYSES = ("modal",)
# polings whose material axes are r, theta, z: the cos n theta and sin n theta parts do not couple
FOURIER_POLINGS = ("+z", "-z", "radial", "-radial")
POLING_VECTORS = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
                  "+z": (0, 0, 1), "-z": (0, 0, -1)}


def build_mesh(case: Case, comm: MPI.Comm) -> MeshData:
    geo = case.geometry
    if geo.builder is not None:
        params_cls, build = BUILDERS[geo.builder]
        params = from_dict(params_cls, geo.parameters, case.source, "geometry.parameters")
        try:
            return build(comm, params, geo.model)
        except ValueError as exc:
            raise CaseError(case.source, "geometry.model", str(exc)) from None
    path = Path(geo.mesh_file)
    if not path.is_absolute():
        path = Path(case.source).parent / path
    gdim = 3 if geo.model == "3d" else 2
    return read_msh(comm, path, gdim, case.source)


def _tag(names: dict[str, int], ref, file, key, what) -> int:
    if isinstance(ref, int):
        if ref in names.values():
            return ref
    elif ref in names:
        return names[ref]
    known = ", ".join(f"{n}={t}" for n, t in names.items()) or "none"
    raise CaseError(file, key, f"{what} group {ref!r} is not in the mesh (mesh has: {known})")


def facet_group_tag(names: dict[str, int], ref, file, key) -> int:
    """Tag of the facet group ``ref`` (name or tag); CaseError naming ``key`` if the mesh lacks it."""
    return _tag(names, ref, file, key, "facet")


@dataclass
class Region:
    name: str
    tag: int
    material_name: str
    density_kg_per_m3: float
    quality_factor: float | None
    c: object  # UFL 6x6 [Pa] in global axes
    e: object | None
    eps: object | None


@dataclass
class FEModel:
    case: Case
    comm: MPI.Comm
    kind: str
    mesh_data: MeshData
    W: fem.FunctionSpace
    regions: list[Region]
    stiffness: ufl.Form
    mass: ufl.Form
    material_stiffness: dict[str, ufl.Form]
    electrode_dofs: dict[str, np.ndarray]
    grounded_dofs: np.ndarray
    support_dofs: np.ndarray
    point_probes: dict = field(default_factory=dict)
    circumferential_order: int | None = None   # n of a Fourier-harmonic model

    @property
    def form_kind(self):
        """The kinematics the forms take (forms.kinematics.kinematics): the kind, or Fourier(n)."""
        return kinematics(self.kind, self.circumferential_order)

    @property
    def mesh(self):
        return self.mesh_data.mesh

    def electrodes_of(self, kind: str) -> list[str]:
        return [n for n, e in self.case.electrodes.items() if e.kind == kind]

    def damping(self, reference_frequency_Hz: float) -> ufl.Form | None:
        """C = alpha M + sum_j (beta + beta_j) K_j (drill paper eqs. 3-4) at the given omega."""
        d = self.case.damping
        betas = []
        for region in self.regions:
            q = region.quality_factor if d.material_quality else None
            betas.append(dynamics.material_damping_beta(reference_frequency_Hz, q) if q else 0.0)
        forms = [self.material_stiffness[r.name] for r in self.regions]
        return dynamics.rayleigh_damping(self.mass, forms, d.alpha_per_s, d.beta_s, betas)

    def total_mass_kg(self) -> float:
        # the body's own volume: a Fourier model's weight of order n >= 1 is pi r (the mean of cos^2), its volume 2 pi r
        kind = kinematics(self.kind, 0) if self.kind == "fourier" else self.kind
        total = sum(r.density_kg_per_m3 * volume_weight(self.mesh, kind, self.case.geometry.thickness_m)
                    * self._dx(r.tag) for r in self.regions)
        return self.comm.allreduce(fem.assemble_scalar(fem.form(total)), op=MPI.SUM)

    def displacement(self, x) -> fem.Function:
        """Displacement part of a full u-phi PETSc vector as a Function on the collapsed space."""
        if not hasattr(self, "_u_space"):
            self._u_space, self._u_map = self.W.sub(0).collapse()
            self._u_fun = fem.Function(self._u_space, name="displacement")
        n_owned = self._u_space.dofmap.index_map.size_local * self._u_space.dofmap.index_map_bs
        self._u_fun.x.array[:n_owned] = x.array_r[self._u_map[:n_owned]]
        self._u_fun.x.scatter_forward()
        return self._u_fun

    def point_values(self, x) -> dict[str, float]:
        """Displacement component [m] at each named point for a full u-phi vector ``x``."""
        u = self.displacement(x)
        return {name: float(probe(u)[comp]) for name, (probe, comp) in self.point_probes.items()}

    def _dx(self, tag):
        return ufl.Measure("dx", domain=self.mesh, subdomain_data=self.mesh_data.cell_tags)(tag)


def _material_tensors(case: Case, region_cfg, index: int, mesh, kind: str):
    material = case.materials[region_cfg.material]
    c, e, eps = material.tensors()
    poling = region_cfg.poling
    x = ufl.SpatialCoordinate(mesh)
    if poling in ("radial", "-radial"):
        sign = 1.0 if poling == "radial" else -1.0
        if kind == "3d":
            frame = radial_frame = voigt.radial_frame_3d(x)
            if sign < 0:
                frame = ufl.dot(radial_frame, ufl.as_matrix([[1, 0, 0], [0, -1, 0], [0, 0, -1]]))
            if e is None:
                return fem.Constant(mesh, c), None, None
            return (voigt.rotate_stiffness(fem.Constant(mesh, c), frame),
                    voigt.rotate_piezo_e(fem.Constant(mesh, e), frame),
                    voigt.rotate_permittivity(fem.Constant(mesh, eps), frame))
        if kind == "plane_strain":
            raise CaseError(case.source, f"regions[{index}].poling", "radial poling needs axisymmetric, fourier or 3d")
        frame = voigt.frame_from_poling((sign, 0, 0))
    else:
        if kind == "fourier" and e is not None and poling not in FOURIER_POLINGS:
            raise CaseError(case.source, f"regions[{index}].poling", "a Fourier-harmonic model needs material "
                            f"axes r, theta, z: poling one of {', '.join(FOURIER_POLINGS)}")
        vector = POLING_VECTORS[poling] if isinstance(poling, str) else poling
        frame = voigt.frame_from_poling(vector)
    c_g = voigt.rotate_stiffness(c, frame)
    if e is None:
        return fem.Constant(mesh, c_g), None, None
    return (fem.Constant(mesh, c_g), fem.Constant(mesh, voigt.rotate_piezo_e(e, frame)),
            fem.Constant(mesh, voigt.rotate_permittivity(eps, frame)))


def _check_electrodes_apart(case: Case, electrode_dofs: dict[str, np.ndarray], comm: MPI.Comm) -> None:
    """An electrode is an equipotential surface with its own potential (driven, floating) or charge: two
    electrodes may share a potential DOF (facet groups meeting at an edge) only if both are ground, held at
    the same 0 V. Two driven electrodes would each prescribe the shared DOFs, two floating ones would be one
    equipotential, and a shared DOF's charge would be counted for both. Collective."""
    names = list(electrode_dofs)
    for a_i, a in enumerate(names):
        for b in names[a_i + 1:]:
            kinds = (case.electrodes[a].kind, case.electrodes[b].kind)
            if kinds != ("ground", "ground") and comm.allreduce(
                    np.intersect1d(electrode_dofs[a], electrode_dofs[b]).size) > 0:
                raise CaseError(case.source, f"electrodes.{b}.facets",
                                f"shares potential DOFs with electrode {a!r} (kinds {kinds[1]!r} and {kinds[0]!r}): "
                                "only ground electrodes may touch; merge them into one electrode or part them")


def _axis_conditions(kind: str, order: int | None, n_axis_facets: int, file) -> tuple[list[int], bool]:
    """(displacement components held at 0 on the axis r = 0, whether the potential is too) of a model of
    revolution: u_r in an axisymmetric model; in a Fourier model of order n, u_r and u_theta for n = 0,
    everything for n >= 2 (the fields of those orders vanish on the axis). Order 1 (u_z and phi vanish,
    u_r = -u_theta: a constraint between components) is refused when the mesh reaches the axis."""
    if kind == "axisymmetric":
        return [0], False
    if order == 0:
        return [0, 1], False
    if order == 1 and n_axis_facets:
        raise CaseError(file, "geometry.circumferential_order", "order 1 on a mesh that reaches the axis r = 0 is "
                                                                "not supported (it needs u_r = -u_theta there)")
    return [0, 1, 2], True


def build_model(case: Case, comm: MPI.Comm = MPI.COMM_WORLD, mesh_data: MeshData | None = None) -> FEModel:
    file = case.source
    kind = case.geometry.model
    order = case.geometry.circumferential_order if kind == "fourier" else None
    form_kind = kinematics(kind, order)
    if kind == "fourier":
        for i, analysis in enumerate(case.analyses or []):
            if analysis not in FOURIER_ANALYSES:
                raise CaseError(file, f"analyses[{i}]", f"a Fourier-harmonic model (geometry.model = 'fourier') runs "
                                                        f"{', '.join(FOURIER_ANALYSES)} only, not {analysis!r}")
    md = mesh_data or build_mesh(case, comm)
    mesh = md.mesh
    tdim = mesh.topology.dim
    fdim = tdim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    W = mixed_space(mesh, case.geometry.degree, displacement_components(form_kind))
    (u, phi), (v, psi) = ufl.TrialFunctions(W), ufl.TestFunctions(W)
    metadata = {} if case.geometry.quadrature_degree is None else {"quadrature_degree": case.geometry.quadrature_degree}
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=md.cell_tags, metadata=metadata)
    weight = volume_weight(mesh, form_kind, case.geometry.thickness_m)

    mesh_tags = set(np.unique(np.concatenate(comm.allgather(md.cell_tags.values))).tolist())
    regions, covered = [], set()
    stiffness = mass = None
    material_stiffness = {}
    grounded_cells = []
    for i, cfg in enumerate(case.regions):
        tag = _tag(md.cell_names, cfg.cells, file, f"regions[{i}].cells", "cell")
        if tag in covered:
            raise CaseError(file, f"regions[{i}].cells", f"cell group {cfg.cells!r} is assigned twice")
        covered.add(tag)
        material = case.materials[cfg.material]
        c, e, eps = _material_tensors(case, cfg, i, mesh, kind)
        name = str(cfg.cells)
        region = Region(name, tag, cfg.material, material.density_kg_per_m3, material.quality_factor, c, e, eps)
        regions.append(region)
        k_form = (piezo.coupled_stiffness(u, phi, v, psi, c, e, eps, form_kind, dx(tag), weight) if e is not None
                  else piezo.elastic_stiffness(u, v, c, form_kind, dx(tag), weight))
        if e is None:
            grounded_cells.append(md.cell_tags.indices[md.cell_tags.values == tag])
        m_form = dynamics.mass(u, v, fem.Constant(mesh, material.density_kg_per_m3), dx(tag), weight)
        material_stiffness[name] = piezo.elastic_stiffness(u, v, c, form_kind, dx(tag), weight)
        stiffness = k_form if stiffness is None else stiffness + k_form
        mass = m_form if mass is None else mass + m_form
    missing = mesh_tags - covered
    if missing:
        inverse = {t: n for n, t in md.cell_names.items()}
        names = ", ".join(repr(inverse.get(t, t)) for t in sorted(missing))
        raise CaseError(file, "regions", f"cell groups without a region: {names}")

    W1 = W.sub(1)
    cells = np.concatenate(grounded_cells) if grounded_cells else np.zeros(0, dtype=np.int32)
    grounded = fem.locate_dofs_topological(W1, tdim, cells)
    electrode_dofs = {}
    tag_owner = {}
    for name, electrode in case.electrodes.items():
        facets = []
        for j, ref in enumerate(electrode.facets):
            key = f"electrodes.{name}.facets[{j}]"
            tag = _tag(md.facet_names, ref, file, key, "facet")
            owner = tag_owner.setdefault(tag, (name, ref))
            if owner != (name, ref):        # the same group by name and by tag
                raise CaseError(file, key, f"facet group {ref!r} is the group {owner[1]!r} of electrode {owner[0]!r} "
                                           "(a facet belongs to one electrode at most)")
            facets.append(md.facet_tags.indices[md.facet_tags.values == tag])
        dofs = fem.locate_dofs_topological(W1, fdim, np.concatenate(facets))
        if electrode.kind != "ground" and comm.allreduce(np.intersect1d(dofs, grounded).size) > 0:
            raise CaseError(file, f"electrodes.{name}.facets",
                            "touches a non-piezoelectric region, whose potential is held at 0 V")
        if comm.allreduce(dofs.size) == 0:
            groups = ", ".join(map(repr, electrode.facets))
            raise CaseError(file, f"electrodes.{name}.facets", f"selects no potential DOFs (facet group(s) {groups} "
                                                                "hold no facet of the mesh)")
        electrode_dofs[name] = dofs
    _check_electrodes_apart(case, electrode_dofs, comm)
    wave = case.harmonic.wave if case.harmonic is not None else None
    for j, other in enumerate(wave.balance_with if wave is not None else []):
        if other not in case.electrodes or case.electrodes[other].kind != "voltage" or other == wave.balance:
            raise CaseError(file, f"harmonic.wave.balance_with[{j}]", f"{other!r} is not another electrode of kind "
                                                                     "'voltage'")

    supports = [np.zeros(0, dtype=np.int32)]
    comp = COMPONENTS[kind]
    held = {}
    for i, support in enumerate(case.supports):
        facets, tags = [], []
        for j, ref in enumerate(support.facets):
            tag = _tag(md.facet_names, ref, file, f"supports[{i}].facets[{j}]", "facet")
            tags.append((j, ref, tag))
            facets.append(md.facet_tags.indices[md.facet_tags.values == tag])
        for j, name in enumerate(support.components):
            if name not in comp:
                raise CaseError(file, f"supports[{i}].components[{j}]",
                                f"{name!r} is not a component of a {kind} model ({', '.join(comp)})")
            for k, ref, tag in tags:        # by tag and component index ('r' and 'x' are one component here)
                if (tag, comp[name]) in held:
                    other, other_ref, other_name = held[tag, comp[name]]
                    key = f"components[{j}]" if (other, repr(other_ref)) == (i, repr(ref)) else f"facets[{k}]"
                    raise CaseError(file, f"supports[{i}].{key}", f"component {name!r} of facet group {ref!r} is "
                                    f"already held by supports[{other}] (as {other_name!r} of {other_ref!r})")
                held[tag, comp[name]] = (i, ref, name)
            supports.append(fem.locate_dofs_topological(W.sub(0).sub(comp[name]), fdim, np.concatenate(facets)))
    if kind in ("axisymmetric", "fourier"):
        axis = dmesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 0.0, atol=1e-12))
        held, potential_held = _axis_conditions(kind, order, comm.allreduce(axis.size), file)
        for sub in held:
            supports.append(fem.locate_dofs_topological(W.sub(0).sub(sub), fdim, axis))
        if potential_held:
            grounded = np.union1d(grounded, fem.locate_dofs_topological(W1, fdim, axis))
    support_dofs = np.unique(np.concatenate(supports)).astype(np.int32)

    model = FEModel(case, comm, kind, md, W, regions, stiffness, mass, material_stiffness, electrode_dofs,
                    grounded.astype(np.int32), support_dofs, circumferential_order=order)
    from app.fe.probe import PointProbe

    for name, point in case.points.items():
        if point.component not in comp:
            raise CaseError(file, f"points.{name}.component", f"{point.component!r} is not a component of a "
                            f"{kind} model")
        if len(point.coordinates_m) != mesh.geometry.dim:
            raise CaseError(file, f"points.{name}.coordinates_m", f"needs {mesh.geometry.dim} coordinates")
        probe = PointProbe(mesh, np.array(point.coordinates_m, dtype=float))
        if not probe.found:
            raise CaseError(file, f"points.{name}.coordinates_m", "point lies outside the mesh")
        model.point_probes[name] = (probe, comp[point.component])
    return model
