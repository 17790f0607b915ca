"""The reduced model of a case for the modal tier: its FE model reduced on a Craig-Bampton basis whose interface
is where the case's contacts act, and everything the compiled loop needs that depends on the mesh and the
basis (reduced operators, site rows, point rows, charge rows, load projections, the vertex basis for field
output) as plain arrays: cacheable and saved with the checkpoint.

Interface coordinates (app/reduced/sites.py): a node contact's node; a surface contact's nodes (all of them,
or ``reduction.interface_nodes`` of them). Inputs: the driven electrodes (a potential of 1 V on the
electrode) and each base motion's four spatial patterns (n cos kx, n sin kx, e cos kx, e sin kx: a travelling
wave is their combination with time functions, app/reduced/loop_kernel.py).

What the model depends on, and only that, keys its cache (``PIEZODYN_CACHE_DIR``, default
~/.cache/piezodyn): the mesh and materials, electrodes' kinds and facets (not their voltages or phases),
supports, damping, the basis settings, the contacts' surfaces and sampling, the base motions' geometry, the
points, the enrichment's frequency, and the damping's reference frequency where material quality factors
use it. So a sweep over voltage, load, preload, friction, rotor or step sizes builds it once; a sweep over the
drive frequency builds it once where the basis does not follow that frequency (``reduction.cutoff_Hz`` or
``n_modes`` given, no enrichment or ``enrich_near_Hz`` given, no material-quality damping or its
``reference_frequency_Hz`` given), and a sweep over a locked drive's ``transient.drive.detuning_Hz`` builds it
once always (the basis follows the nominal frequency): tests/test_reduced_cache.py counts the builds. The key holds
the frequencies the build uses (the cutoff in Hz, the enrichment target), not how the case states them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from app.contact.sites import contact_site_sets
from app.errors import CaseError, NumericalFailure

CACHE_VERSION = 5
# fields a saved model may lack (saved before they existed): load() gives them their empty values
OPTIONAL_FIELDS = ("derived_basis", "region_table")


@dataclass
class ReducedModel:
    """Arrays of a reduced model (replicated on every rank). Coordinates: ``n_interface`` interface
    displacements [m], one per input (electrode potentials [V], then base-motion pattern amplitudes), then
    modal amplitudes."""

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray
    n_interface: int
    inputs: list                     # input coordinate names: electrodes, then "<motion>:<pattern>"
    n_electrodes: int
    mode_frequencies_Hz: np.ndarray
    enrichment_frequencies_Hz: np.ndarray
    charge_rows: np.ndarray          # (n_electrodes, n): Q_e [C] = row @ q
    translation_loads: np.ndarray    # (gdim, n): T^T M t_k, the generalized load of a unit acceleration along k
    sample_names: list               # named points
    sample_rows: np.ndarray          # (n_points, n): the point's displacement component = row @ q
    site_points: np.ndarray          # (n_sites, 3) reference positions [m]
    site_weight: np.ndarray          # (n_sites,) areas [m^2] (1: a node)
    site_contact: np.ndarray         # (n_sites,) index of the contact in the case
    site_rows: np.ndarray            # (n_sites * gdim, n)
    gdim: int
    band_area_m2: np.ndarray         # (n_contacts,) area of each contact's facet group (0: not a surface)
    vertex_basis: np.ndarray         # (n_vertices * (3 + 1), n) displacement and potential at the vertices, or (0, n)
    mesh_geometry: np.ndarray        # vertex coordinates (input order), for field output
    mesh_topology: np.ndarray
    mesh_region: np.ndarray
    mesh_topology_type: str
    # derived fields by expansion: strain, stress, E, D (app.fe.derived.RAW columns) of each basis vector, averaged
    # region by region at the vertices (app.fe.derived.RegionAveraging of mesh_topology and mesh_region),
    # (n_pairs * 18, n), or (0, n); and "tag|name|piezoelectric (0/1)" of every region
    derived_basis: np.ndarray
    region_table: list
    reduction_wall_s: float
    fe_dofs: int
    mass_kg: float                   # the FE structure's mass (the downforce acts like it)

    @property
    def size(self) -> int:
        return self.K.shape[0]

    @property
    def input_coordinates(self) -> np.ndarray:
        """The prescribed inputs' positions among the coordinates (electrode potentials, base-motion patterns: they
        follow the interface ones), int64."""
        return np.arange(self.n_interface, self.n_interface + len(self.inputs), dtype=np.int64)

    @property
    def free_coordinates(self) -> np.ndarray:
        """Every other coordinate's position (interface, modal), ascending, int64."""
        return np.setdiff1d(np.arange(self.size), self.input_coordinates).astype(np.int64)

    def resonances_Hz(self, near_Hz: float, count: int = 2) -> np.ndarray:
        """The reduced structure's ``count`` natural frequencies nearest ``near_Hz`` with every input held
        (short circuit, as the driven transient sees them) [Hz], ascending."""
        import scipy.linalg

        keep = self.free_coordinates
        values = scipy.linalg.eigh(self.K[np.ix_(keep, keep)], self.M[np.ix_(keep, keep)], eigvals_only=True)
        frequencies = np.sqrt(np.abs(values)) / (2 * math.pi)
        return np.sort(frequencies[np.argsort(np.abs(frequencies - near_Hz))[:count]])

    def save(self, fh) -> None:
        arrays = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            arrays[f.name] = np.array(value, dtype=str) if f.name in ("inputs", "sample_names", "mesh_topology_type",
                                                                      "region_table") \
                else np.asarray(value)
        np.savez(fh, **arrays)

    @classmethod
    def load(cls, path: Path) -> ReducedModel:
        """Raises KeyError (a field missing: another version), OSError, ValueError (unreadable)."""
        values = {}
        with np.load(path, allow_pickle=False) as f:
            for field in dataclasses.fields(cls):
                if field.name in OPTIONAL_FIELDS and field.name not in f:
                    continue
                value = f[field.name]
                if field.name in ("inputs", "sample_names", "region_table"):
                    values[field.name] = [str(v) for v in value]
                elif field.name == "mesh_topology_type":
                    values[field.name] = str(value)
                elif field.name in ("n_interface", "n_electrodes", "gdim", "fe_dofs"):
                    values[field.name] = int(value)
                elif field.name in ("reduction_wall_s", "mass_kg"):
                    values[field.name] = float(value)
                else:
                    values[field.name] = np.array(value)
        if "derived_basis" not in values:         # a model saved before the derived fields (a format-1 checkpoint)
            values["derived_basis"] = np.zeros((0, values["K"].shape[0]))
            values["region_table"] = []
        return cls(**values)


# ------------------------------------------------------------------ the cache
def cache_key(case) -> str:
    """What the reduced model depends on (module docstring), hashed."""
    from app.case.validate import to_dict

    data = to_dict(case)
    cfg = data["transient"]
    electrodes = {name: {"kind": e["kind"], "facets": e["facets"]} for name, e in data["electrodes"].items()}
    contacts = []
    for c in cfg["contacts"]:
        if c["kind"] == "point":
            continue
        keep = {k: c.get(k) for k in ("kind", "facets", "node_point", "sampling", "sample_points", "shape", "axis",
                                      "radius_m", "half_angle_deg", "body", "friction")}
        if c.get("sample_rings", 1) != 1:           # the default: the keys of models built before the key existed
            keep["sample_rings"] = c["sample_rings"]
        keep["friction"] = c.get("friction") is not None        # node DOFs kept: all components with friction
        contacts.append(keep)
    bodies = {b["name"]: {"position_m": b["position_m"], "rotations": [r["axis"] for r in b["rotations"]]}
              for b in cfg["bodies"]}
    motions = [{k: m[k] for k in ("facets", "wavelength_m", "direction", "normal")} for m in cfg["base_motions"]]
    # the basis's frequencies as the build uses them (cutoff_Hz or cutoff_factor x the drive; the enrichment target;
    # the damping's reference): a case that states them and one that takes them from the drive hash alike (a drive
    # locked to the resonance states them: app/drive.py locked_case)
    reduction = dict(data["reduction"])
    # the surgery's keys act on the built model (app/reduced/surgery.py): one cached model for every step of a chain
    for key in ("cutoff_Hz", "cutoff_factor", "enrich_near_Hz", "surgery", "site_motion", "wave_scale"):
        reduction.pop(key, None)
    if reduction.get("interface") == "nodes":       # the default: the keys of models built before the key existed
        reduction.pop("interface")
    red = case.reduction
    reduction["cutoff_Hz_used"] = None if red.n_modes is not None else (
        red.cutoff_Hz if red.cutoff_Hz is not None else red.cutoff_factor * cfg["drive"]["frequency_Hz"])
    damping = {k: v for k, v in data["damping"].items() if k != "reference_frequency_Hz"}
    relevant = {"version": CACHE_VERSION, "geometry": data["geometry"], "materials": repr(case.materials),
                "regions": data["regions"], "electrodes": electrodes, "supports": data["supports"],
                "damping": damping, "reduction": reduction, "contacts": contacts, "bodies": bodies,
                "motions": motions, "points": data["points"], "fields": bool(case.output.fields),
                "derived": list(case.output.derived) if case.output.fields else [],
                "enrich_near_Hz": (case.reduction.enrich_near_Hz or cfg["drive"]["frequency_Hz"])
                if case.reduction.enrich_modes else None,
                # the reference frequency sets the material-quality terms beta_j = 1 / (omega Q_j) only
                "damping_Hz": (case.damping.reference_frequency_Hz or cfg["drive"]["frequency_Hz"])
                if case.damping.material_quality else None}
    text = json.dumps(relevant, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def cache_dir() -> Path:
    return Path(os.environ.get("PIEZODYN_CACHE_DIR", Path.home() / ".cache" / "piezodyn"))


def load_or_build(case, comm, log) -> tuple[ReducedModel, bool]:
    """(the reduced model of ``case``, True if it came from the cache). Rank 0 reads and writes the cache;
    every rank gets rank 0's model (the loop runs replicated and its checkpoints are collective)."""
    path = cache_dir() / f"reduced-{cache_key(case)}.npz"
    found = path.is_file() if comm.rank == 0 else None
    found = comm.bcast(found, root=0) if comm.size > 1 else found
    if found:
        from app.loop.checkpoint import read_on_root

        model = read_on_root(path, comm, ReducedModel.load, "a reduced model")
        log(f"modal tier: reduced model from the cache {path}")
        return model, True
    model = build_reduced_model(case, comm, log)
    if comm.size > 1:
        model = comm.bcast(model if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}.npz")     # per process: sweep points may build it at once
        with open(tmp, "wb") as fh:
            model.save(fh)
        os.replace(tmp, path)
    return model, False


# ------------------------------------------------------------------ building
def base_motion_patterns(case, model) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each travelling-wave base motion's four patterns (n cos kx, n sin kx, e cos kx, e sin kx) on its DOFs:
    name -> (local DOFs, values at unit amplitude)."""
    from app.transient.motions import build_motions

    out = {}
    for motion in build_motions(case, model):
        along = motion.coordinates_m @ motion.direction
        kx = motion.wavenumber_per_m * along
        n_comp = motion.normal[motion.axis]
        e_comp = motion.direction[motion.axis]
        for label, values in (("n_cos", np.cos(kx) * n_comp), ("n_sin", np.sin(kx) * n_comp),
                              ("e_cos", np.cos(kx) * e_comp), ("e_sin", np.sin(kx) * e_comp)):
            out[f"{motion.name}:{label}"] = (motion.dofs, values)
    return out


def build_reduced_model(case, comm, log) -> ReducedModel:
    """Reduce the case's FE model (collective)."""
    from app.fe.model import build_model
    from app.fe.operators import assemble_operators
    from app.reduced.craig_bampton import reduce_model

    start = time.perf_counter()
    cfg = case.transient
    file = case.source
    phases = {}                    # wall time of each phase [s], logged (BENCHMARKS.md, issue 27)
    mark = _clock()
    model = build_model(case, comm)
    phases["mesh and FE model"] = _since(mark)
    if model.electrodes_of("floating"):
        raise CaseError(file, "electrodes", "floating electrodes are not supported by the transient analysis")
    gdim = model.mesh.geometry.dim
    mark = _clock()
    sets, interface, areas = contact_site_sets(case, model)
    phases["contact sites"] = _since(mark)
    damping_Hz = case.damping.reference_frequency_Hz or cfg.drive.frequency_Hz
    log(f"modal tier: assembling {model.W.dofmap.index_map.size_global * model.W.dofmap.index_map_bs} DOFs")
    mark = _clock()
    ops = assemble_operators(model, damping_frequency_Hz=damping_Hz)
    phases["assembly"] = _since(mark)
    fixed = np.concatenate([model.support_dofs, model.grounded_dofs]
                           + [model.electrode_dofs[n] for n in model.electrodes_of("ground")])
    electrodes = {n: model.electrode_dofs[n] for n in model.electrodes_of("voltage")}
    patterns = base_motion_patterns(case, model)
    red = case.reduction
    cutoff = red.cutoff_Hz if red.cutoff_Hz is not None else (
        None if red.n_modes is not None else red.cutoff_factor * cfg.drive.frequency_Hz)
    log(f"modal tier: Craig-Bampton basis: {interface.size} interface DOFs, {len(electrodes)} electrodes, "
        f"{len(patterns)} base-motion patterns, fixed-interface modes "
        + (f"up to {cutoff:.0f} Hz" if cutoff is not None else f"{red.n_modes}"))
    mark = _clock()
    band_patterns = {}
    if red.interface == "band":
        from app.contact.sites import ring_band_patterns

        for s in sets:
            if s.ring is not None:
                band_patterns.update(ring_band_patterns(s.ring, s.interface_dofs))
        log(f"modal tier: band interface: {sum(v[0].size for v in band_patterns.values())} band DOF entries follow "
            f"{len(band_patterns)} interface coordinates")
    basis = reduce_model(ops.K, ops.M, ops.C, model.W, fixed, interface, electrodes, n_modes=red.n_modes,
                         cutoff_Hz=cutoff, n_enrich=red.enrich_modes,
                         enrich_near_Hz=red.enrich_near_Hz or cfg.drive.frequency_Hz, patterns=patterns,
                         interface_patterns=band_patterns)
    phases["reduction (static modes, eigen, enrichment, projection)"] = _since(mark)
    mark = _clock()
    n = basis.size
    # load projections: T^T M t_k per axis (gravity and the downforce act like the body's mass)
    loads = np.zeros((gdim, n))
    for k in range(gdim):
        translation = ops.M.createVecRight()
        _, sub = model.W.sub(0).sub(k).collapse()
        sub = np.asarray(sub)
        translation.array_w[sub[sub < translation.getLocalSize()]] = 1.0
        load = ops.M.createVecLeft()
        ops.M.mult(translation, load)
        loads[k] = basis.project_vector(load)
        translation.destroy()
        load.destroy()
    ops.destroy()
    rows = site_rows(sets, interface, basis, model, gdim)
    sample_names = list(case.points)
    samples = np.zeros((len(sample_names), n))
    for j, column in enumerate(basis.columns):
        values = model.point_values(column)
        for i, name in enumerate(sample_names):
            samples[i, j] = values[name]
    phases["loads, site and point rows"] = _since(mark)
    mark = _clock()
    vertex, geometry, topology, region, topology_type, derived = _vertex_basis(model, basis) if case.output.fields \
        else (np.zeros((0, n)), np.zeros((0, 3)), np.zeros((0, 0), np.int64), np.zeros(0, np.int32), "",
              np.zeros((0, n)))
    region_table = [f"{r.tag}|{r.name}|{int(r.e is not None)}" for r in model.regions]
    n_el = len(electrodes)
    charge = np.array([basis.charge_rows[name] for name in list(electrodes)]).reshape(n_el, n)
    phases["vertex basis and charges"] = _since(mark)
    wall = time.perf_counter() - start
    # wall and CPU time of each phase (one rank: on a shared machine the CPU time is what the load does not inflate)
    log("modal tier: build phases: " + _phase_line(phases))
    log("modal tier: reduction phases: " + _phase_line(basis.phases))
    points = np.concatenate([s.points_m for s in sets]) if sets else np.zeros((0, 3))
    weights = np.concatenate([s.weight for s in sets]) if sets else np.zeros(0)
    contact = np.concatenate([np.full(s.points_m.shape[0], s.contact) for s in sets]) if sets else np.zeros(0, int)
    out = ReducedModel(basis.K, basis.M, basis.C if basis.C is not None else np.zeros_like(basis.K),
                       basis.n_interface, list(basis.electrodes), n_el, basis.mode_frequencies_Hz,
                       basis.enrichment_frequencies_Hz, charge, loads, sample_names, samples, points, weights,
                       contact.astype(np.int64), rows, gdim, areas, vertex, geometry, topology, region, topology_type,
                       derived, region_table, wall,
                       int(model.W.dofmap.index_map.size_global * model.W.dofmap.index_map_bs),
                       float(model.total_mass_kg()))
    log(f"modal tier: {basis.n_interface} interface DOFs, {len(basis.electrodes)} inputs, {basis.n_modes} "
        f"fixed-interface modes up to {basis.mode_frequencies_Hz.max(initial=0.0):.0f} Hz"
        + (f", the full model's modes at {', '.join(f'{f:.1f}' for f in basis.enrichment_frequencies_Hz)} Hz"
           if basis.enrichment_frequencies_Hz.size else "")
        + f", {n} coordinates, {points.shape[0]} contact sites ({wall:.1f} s)")
    basis.destroy()
    return out


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(mark: tuple[float, float]) -> tuple[float, float]:
    """(wall, CPU) seconds since ``mark`` (a ``_clock()``)."""
    wall, cpu = _clock()
    return wall - mark[0], cpu - mark[1]


def _phase_line(phases: dict) -> str:
    return ", ".join(f"{name} {wall:.1f} s (CPU {cpu:.1f} s)" for name, (wall, cpu) in phases.items())


def site_rows(sets, interface: np.ndarray, basis, model, gdim: int) -> np.ndarray:
    """(n_sites * gdim, n) displacement rows of every site: T at a node site's DOFs; a ring's sites
    interpolated from its interface nodes or evaluated in the reduced field (app/reduced/sites.py)."""
    from app.contact.sites import ring_interface_rows

    n = basis.size
    position = {int(d): j for j, d in enumerate(interface)}
    blocks = []
    for s in sets:
        if s.node_dofs is not None:
            blocks.append(_rows_at_dofs(s.node_dofs, basis, model))
        elif s.ring["rule"] == "interface":
            first = position[int(next(d for d in s.interface_dofs.reshape(-1) if d >= 0))]
            full = ring_interface_rows(s.ring, first, gdim, n)
            blocks.append(full.reshape(-1, 3, n)[:, :gdim, :].reshape(-1, n))
        else:
            blocks.append(_rows_at_points(s.points_m[:, :gdim], basis, model, s.name))
    return np.concatenate(blocks) if blocks else np.zeros((0, n))


def _rows_at_dofs(dofs: np.ndarray, basis, model) -> np.ndarray:
    """T at global displacement DOFs (n_nodes, gdim), -1 (held) giving zero rows."""
    comm = basis.comm
    lo, hi = basis.columns[0].getOwnershipRange() if basis.columns else (0, 0)
    flat = dofs.reshape(-1)
    out = np.zeros((flat.size, basis.size))
    mine = (flat >= lo) & (flat < hi)
    for j, column in enumerate(basis.columns):
        if mine.any():
            out[mine, j] = column.getValues(flat[mine].astype(np.int32))
    return comm.allreduce(out, op=MPI.SUM) if comm.size > 1 else out


def _rows_at_points(points: np.ndarray, basis, model, name: str) -> np.ndarray:
    """The reduced field at points: each basis vector's displacement there, (n_points * gdim, n)."""
    from dolfinx import fem

    from app.fe.probe import PointSet

    gdim = points.shape[1]
    probe = PointSet(model.mesh, points)
    if probe.missing.size:
        raise NumericalFailure(f"contact {name!r}: {probe.missing.size} sample points lie outside the mesh "
                               f"(the first at {points[probe.missing[0]].tolist()})")
    f = fem.Function(model.W)
    V, parent = model.W.sub(0).collapse()          # the displacement space: eval takes no mixed element
    parent = np.asarray(parent)
    u = fem.Function(V)
    n_owned = model.W.dofmap.index_map.size_local * model.W.dofmap.index_map_bs
    out = np.zeros((points.shape[0] * gdim, basis.size))
    for j, column in enumerate(basis.columns):
        f.x.array[:n_owned] = column.array_r
        f.x.scatter_forward()
        u.x.array[:] = f.x.array[parent]
        values = probe(u)
        out[:, j] = values[:, :gdim].reshape(-1)
    return out


def _vertex_basis(model, basis):
    """Displacement and potential of every basis vector at the mesh vertices (rank 0's arrays; the field output
    is then V q), the mesh in input order, and when ``output.derived`` lists any, the derived fields' raw columns
    (strain, stress, E, D, app.fe.derived) of every basis vector averaged region by region at the vertices
    (app.fe.derived.RegionAveraging): linear in the
    displacement and potential, so a frame's are the same combination D q, computed once here."""
    from app.exports import VertexFields

    derived = model.case.output.derived
    vertex = VertexFields(model, derived)
    columns, derived_columns = [], []
    for column in basis.columns:
        sampled = vertex.sample(column)
        raw = vertex.sample_derived(column) if derived else None
        if model.comm.rank == 0:
            u, phi = sampled
            columns.append(np.concatenate([u.reshape(-1), phi.reshape(-1)]))
            if derived:
                derived_columns.append(vertex.averaging.average(raw).reshape(-1))
    if model.comm.rank != 0:
        return (np.zeros((0, basis.size)), np.zeros((0, 3)), np.zeros((0, 0), np.int64), np.zeros(0, np.int32), "",
                np.zeros((0, basis.size)))
    arrays = vertex.mesh_arrays
    derived_basis = np.column_stack(derived_columns) if derived_columns else np.zeros((0, basis.size))
    return (np.column_stack(columns), arrays["geometry"], arrays["topology"], arrays["region"],
            vertex.topology_type, derived_basis)
