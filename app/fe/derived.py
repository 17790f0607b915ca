"""Derived fields of an FE solution: strain, stress, von Mises stress, principal stresses, electric field
and electric displacement, from the stress-charge law written once in forms/piezo.py
(:func:`forms.piezo.derived_quantities`) with the model's own strain operator (hoop strain u_r / r in an
axisymmetric model, the Fourier amplitudes of a Fourier-harmonic one).

How they are computed: the UFL expressions are evaluated exactly at the vertices of every cell
(:class:`CellVertexEvaluator`, at points a relative 1e-6 inside the cell; with degree-2 displacements the
stress is linear in a straight 3D cell).
They are averaged region by region at each vertex (:class:`RegionAveraging`): the peaks per region come
from a region's own values, and the field files carry one value per vertex (the piezoelectric side of an
interface), see :meth:`app.exports.VertexFields.derived_frame`.

Harmonic results: the field at phase theta is X(theta) = X_re cos theta - X_im sin theta. The maximum over
the cycle of a quantity whose square is a quadratic form of X (von Mises stress, |E|) is solved exactly:
q(theta)^2 = a cos^2 - 2 c sin cos + b sin^2 with a = q_re^2, b = q_im^2, c = <X_re, X_im>_q, whose maximum is
(a + b) / 2 + sqrt(((a - b) / 2)^2 + c^2). The largest principal stress over the cycle is sampled at
:data:`CYCLE_PHASES` phases and refined by a parabola through the best sample and its neighbours.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem

from app.compat import evaluate_expression, expression_at_points
from forms.piezo import derived_quantities

# the [output] derived key's values -> (base name in the files, unit suffix, components, units text)
DERIVED_FIELDS = {
    "strain": ("strain", "", 6, "1 (Voigt xx, yy, zz, yz, xz, xy; engineering shear)"),
    "stress": ("stress", "Pa", 6, "Pa (Voigt xx, yy, zz, yz, xz, xy)"),
    "von_mises": ("von_mises", "Pa", 1, "Pa"),
    "principal_stress": ("principal_stress", "Pa", 3, "Pa (largest first)"),
    "electric_field": ("electric_field", "V_per_m", 3, "V/m"),
    "electric_displacement": ("electric_displacement", "C_per_m2", 3, "C/m^2"),
}
DEFAULT_DERIVED = ("von_mises", "principal_stress", "electric_field")
# columns of the raw per-vertex array: strain, stress, E, D
RAW = {"strain": slice(0, 6), "stress": slice(6, 12), "electric_field": slice(12, 15),
       "electric_displacement": slice(15, 18)}
RAW_COLUMNS = 18
CYCLE_PHASES = 72
VERTEX_INSET = 1e-6
# peak keys, the same in every analysis and tier (harmonic: maxima over the cycle; transient: over the frames)
PEAK_KEYS = ("von_mises_Pa", "max_principal_stress_Pa", "electric_field_V_per_m")

_REFERENCE_VERTICES = {
    "triangle": [[0, 0], [1, 0], [0, 1]],
    "quadrilateral": [[0, 0], [1, 0], [0, 1], [1, 1]],
    "tetrahedron": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    "hexahedron": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]],
}


def derived_for_model(model, names) -> tuple[str, ...]:
    """The derived fields a model writes: all of ``names``, except that a Fourier-harmonic model's stresses are
    the amplitudes of cos n theta and sin n theta parts (forms.kinematics), which are never at their peak at
    the same theta, so their von Mises and principal values would mean nothing: it writes the components."""
    if model.kind == "fourier":
        return tuple(n for n in names if n in RAW)
    return tuple(names)


def field_name(derived: str, part: str = "") -> str:
    """Name of a derived field in the files, its unit last: ``stress_Pa``, ``stress_re_Pa``,
    ``von_mises_cycle_max_Pa``, ``strain``."""
    base, unit = DERIVED_FIELDS[derived][:2]
    return "_".join(p for p in (base, part, unit) if p)


class CellVertexEvaluator:
    """Strain, stress, E and D of a full u-phi vector at the vertices of every owned cell.
    ``evaluate(x)`` (not collective) returns an (owned cells, vertices per cell, 18) array in local cell order,
    columns :data:`RAW`."""

    def __init__(self, model):
        mesh = model.mesh
        self.model = model
        self.w = fem.Function(model.W)
        u, phi = ufl.split(self.w)
        vertices = np.array(_REFERENCE_VERTICES[mesh.topology.cell_type.name], dtype=float)
        # a relative 1e-6 inside the cell: on the axis of a model of revolution u_r / r is 0 / 0 at the vertex
        # itself, and its limit (du_r/dr) is what a point just inside gives
        points = vertices + VERTEX_INSET * (vertices.mean(axis=0) - vertices)
        self.n_vertices = points.shape[0]
        self.n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        tags = model.mesh_data.cell_tags
        self.region_tag = np.zeros(self.n_owned, dtype=np.int32)
        self._parts = []
        for region in model.regions:
            cells = np.asarray(tags.indices[tags.values == region.tag], dtype=np.int32)
            cells = cells[cells < self.n_owned]
            self.region_tag[cells] = region.tag
            S, T, E, D = derived_quantities(u, phi, region.c, region.e, region.eps, model.form_kind)
            columns = ufl.as_vector([S[i] for i in range(6)] + [T[i] for i in range(6)]
                                    + [E[i] for i in range(3)] + [D[i] for i in range(3)])
            self._parts.append((cells, expression_at_points(columns, points)))
        self._n_dofs = model.W.dofmap.index_map.size_local

    def evaluate(self, x) -> np.ndarray:
        self.w.x.array[:self._n_dofs] = x.array_r[:self._n_dofs]
        self.w.x.scatter_forward()
        out = np.zeros((self.n_owned, self.n_vertices, RAW_COLUMNS))
        for cells, expression in self._parts:
            if cells.size:
                values = evaluate_expression(expression, self.model.mesh, cells)
                out[cells] = values.reshape(cells.size, self.n_vertices, RAW_COLUMNS)
        return out


# ---------------------------------------------------------------------------------------- invariants (numpy)
def voigt_tensor(T: np.ndarray) -> np.ndarray:
    """(..., 6) Voigt stress (xx, yy, zz, yz, xz, xy) -> (..., 3, 3) symmetric tensor."""
    out = np.empty(T.shape[:-1] + (3, 3))
    for (i, j), k in {(0, 0): 0, (1, 1): 1, (2, 2): 2, (1, 2): 3, (0, 2): 4, (0, 1): 5}.items():
        out[..., i, j] = out[..., j, i] = T[..., k]
    return out


def voigt_parts(T: np.ndarray) -> list:
    """The six Voigt components (xx, yy, zz, yz, xz, xy) of (..., 6) stresses, as the ``parts`` the invariants
    below take (each an array, or the float 0.0 for a component that is zero everywhere)."""
    return [T[..., i] for i in range(6)]


def von_mises(T: np.ndarray) -> np.ndarray:
    """Von Mises stress [Pa] of (..., 6) Voigt stresses [Pa]."""
    return von_mises_of_parts(voigt_parts(T))


def von_mises_of_parts(parts) -> np.ndarray:
    """Von Mises stress [Pa] of the Voigt components ``parts`` (:func:`voigt_parts`)."""
    return np.sqrt(np.maximum(_vm_parts(parts, parts), 0.0))


def _vm_form(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The symmetric bilinear form whose quadratic form is the von Mises stress squared."""
    return _vm_parts(voigt_parts(A), voigt_parts(B))


def _vm_parts(A, B):
    """:func:`_vm_form` of Voigt components (:func:`voigt_parts`)."""
    d = lambda X: (X[0] - X[1], X[1] - X[2], X[2] - X[0])  # noqa: E731
    return 0.5 * sum(a * b for a, b in zip(d(A), d(B))) + 3.0 * (A[3] * B[3] + A[4] * B[4] + A[5] * B[5])


#: |r| above which principal_stresses hands a tensor to LAPACK (two principal stresses nearly equal)
NEAR_REPEATED = 1.0 - 1e-6
#: a plane of symmetry: (its two shears that vanish, its in-plane normal components and shear, the normal one)
#: in Voigt indices (xx, yy, zz, yz, xz, xy)
_PLANES = (((3, 4), (0, 1, 5), 2), ((3, 5), (0, 2, 4), 1), ((4, 5), (1, 2, 3), 0))


def principal_stresses(T: np.ndarray) -> np.ndarray:
    """(..., 3) principal stresses [Pa], largest first, of (..., 6) Voigt stresses (:func:`principal_of_parts`).
    Agreement with LAPACK's eigvalsh: tests/test_derived_fields.py."""
    T = np.asarray(T, dtype=float)
    return np.stack(principal_of_parts(voigt_parts(T)), axis=-1)


def principal_of_parts(parts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(largest, middle, smallest) principal stress [Pa] of the Voigt components ``parts`` (:func:`voigt_parts`),
    arrays of one shape, 0.0 for a component zero everywhere. Closed forms, not LAPACK's eigvalsh (20x slower on
    3 x 3 tensors, which the field output would run at every vertex of every frame):

    - where two shears are zero at every point (a model of revolution or a plane model: one principal direction
      is normal to the plane), the in-plane pair m +- sqrt(((x - y) / 2)^2 + s^2) with m = (x + y) / 2 and the normal
      stress, sorted: exact to a few machine epsilons of |T| at any spread, repeated values included (the axis of
      a model of revolution, sigma_rr = sigma_thetatheta);
    - else the roots of the characteristic polynomial (the trigonometric solution, q + 2 p cos(phi + 2 pi k / 3)
      with r = det((T - q I) / p) / 2 = cos 3 phi); where two principal stresses nearly coincide
      (|r| > NEAR_REPEATED) it loses digits (an error of sqrt(machine epsilon) |T|), so those tensors go to
      eigvalsh."""
    shape = np.broadcast_shapes(*(np.shape(p) for p in parts))
    for zero, (x, y, s), normal in _PLANES:
        if all(not np.any(parts[i]) for i in zero):
            x, y, s, n = parts[x], parts[y], parts[s], parts[normal]
            h = 0.5 * (x - y)
            m, r = 0.5 * (x + y), np.sqrt(h * h + s * s)
            hi, lo = m + r, m - r
            return tuple(np.broadcast_to(v, shape) for v in
                         (np.maximum(hi, n), np.maximum(lo, np.minimum(hi, n)), np.minimum(lo, n)))
    a, b, c, d, e, f = parts         # xx, yy, zz, yz, xz, xy
    q = (a + b + c) / 3.0
    A, B, C = a - q, b - q, c - q
    p = np.sqrt((A * A + B * B + C * C + 2.0 * (d * d + e * e + f * f)) / 6.0)
    det = A * (B * C - d * d) - f * (f * C - d * e) + e * (f * d - B * e)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(p > 0, det / (2.0 * p ** 3), 0.0)
    phi = np.arccos(np.clip(r, -1.0, 1.0)) / 3.0
    s1 = np.broadcast_to(q + 2.0 * p * np.cos(phi), shape).copy()
    s3 = np.broadcast_to(q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0), shape).copy()
    s2 = np.broadcast_to(3.0 * q - s1 - s3, shape).copy()
    near = np.abs(np.broadcast_to(r, shape)) > NEAR_REPEATED
    if near.any():
        T = np.stack([np.broadcast_to(v, shape)[near] for v in parts], axis=-1)
        s3[near], s2[near], s1[near] = np.linalg.eigvalsh(voigt_tensor(T)).T
    return s1, s2, s3


def _cycle_max(a, b, c) -> np.ndarray:
    """max over theta of a cos^2 - 2 c sin cos + b sin^2 (a, b >= 0)."""
    return np.maximum(0.5 * (a + b) + np.sqrt((0.5 * (a - b)) ** 2 + c * c), 0.0)


def von_mises_cycle_max(T_re: np.ndarray, T_im: np.ndarray) -> np.ndarray:
    """max over the cycle of the von Mises stress of T_re cos theta - T_im sin theta [Pa] (exact)."""
    return np.sqrt(_cycle_max(_vm_form(T_re, T_re), _vm_form(T_im, T_im), _vm_form(T_re, T_im)))


def norm_cycle_max(E_re: np.ndarray, E_im: np.ndarray) -> np.ndarray:
    """max over the cycle of |E_re cos theta - E_im sin theta| (exact)."""
    return np.sqrt(_cycle_max(np.sum(E_re * E_re, -1), np.sum(E_im * E_im, -1), np.sum(E_re * E_im, -1)))


def largest_principal_cycle_max(T_re: np.ndarray, T_im: np.ndarray, phases: int = CYCLE_PHASES,
                                chunk: int = 8192) -> np.ndarray:
    """max over the cycle of the largest principal stress of T_re cos theta - T_im sin theta [Pa]: sampled at
    ``phases`` phases, then the parabola through the best sample and its neighbours (its vertex, clipped to
    the neighbours' interval, is evaluated)."""
    T_re, T_im = T_re.reshape(-1, 6), T_im.reshape(-1, 6)
    theta = 2 * np.pi * np.arange(phases) / phases
    step = theta[1]
    out = np.empty(T_re.shape[0])

    def largest(re, im, th):
        T = re * np.cos(th)[..., None] - im * np.sin(th)[..., None]
        return np.linalg.eigvalsh(voigt_tensor(T))[..., -1]

    for start in range(0, T_re.shape[0], chunk):
        re, im = T_re[start:start + chunk], T_im[start:start + chunk]
        samples = np.stack([largest(re, im, np.full(re.shape[0], th)) for th in theta], axis=1)
        k = np.argmax(samples, axis=1)
        rows = np.arange(re.shape[0])
        y0, y1, y2 = samples[rows, k - 1], samples[rows, k], samples[rows, (k + 1) % phases]
        curvature = y0 - 2 * y1 + y2
        shift = np.where(curvature < 0, 0.5 * (y0 - y2) / np.where(curvature < 0, curvature, -1.0), 0.0)
        refined = largest(re, im, theta[k] + np.clip(shift, -1.0, 1.0) * step)
        out[start:start + chunk] = np.maximum(y1, refined)
    return out


# ------------------------------------------------------------------------------------- fields and peaks
def fields_of(names, raw, von_mises_values, principal_values) -> dict[str, np.ndarray]:
    """The file fields (file name -> array) of the derived quantities ``names`` (``output.derived``) of a real
    solution, however the caller forms them: ``raw(name)`` a tensor's or vector's components (RAW's names),
    ``von_mises_values()`` and ``principal_values()`` the invariants (called only when asked for). Both tiers'
    real fields go through it (:func:`node_fields`, the modal tier's frames), so a new derived quantity is named
    once."""
    out = {}
    for derived in names:
        if derived in RAW:
            out[field_name(derived)] = raw(derived)
        elif derived == "von_mises":
            out[field_name(derived)] = von_mises_values()
        elif derived == "principal_stress":
            out[field_name(derived)] = principal_values()
    return out


def node_fields(averaged: np.ndarray, names, kind: str = "real", columns: dict = RAW) -> dict[str, np.ndarray]:
    """File fields (name -> array) from averaged raw vertex values (n, 18) of a real solution; ``columns``: where
    strain, stress, E and D are in the last axis (another than RAW when only some were formed, see
    :func:`raw_columns`)."""
    stress = averaged[:, columns["stress"]]
    return fields_of(names, lambda name: averaged[:, columns[name]], lambda: von_mises(stress),
                     lambda: principal_stresses(stress))


def harmonic_node_fields(re: np.ndarray, im: np.ndarray, names) -> dict[str, np.ndarray]:
    """File fields of a harmonic solution: real and imaginary parts of the tensors and vectors, and the
    maxima over the cycle of the von Mises stress and of the largest principal stress."""
    out = {}
    for derived in names:
        if derived in RAW:
            out[field_name(derived, "re")] = re[:, RAW[derived]]
            out[field_name(derived, "im")] = im[:, RAW[derived]]
        elif derived == "von_mises":
            out[field_name(derived, "cycle_max")] = von_mises_cycle_max(re[:, RAW["stress"]], im[:, RAW["stress"]])
        elif derived == "principal_stress":
            out["max_principal_stress_cycle_max_Pa"] = largest_principal_cycle_max(re[:, RAW["stress"]],
                                                                                    im[:, RAW["stress"]])
    return out


class RegionAveraging:
    """Region-wise averaged vertex values (ANSYS' material-wise averaging): a value per (region, vertex) pair, the
    mean over the region's cells that share the vertex, so a field that jumps across an interface (E between
    oppositely poled rings and 0 in a grounded metal part, stress across materials) keeps both sides. The files
    carry one value per vertex: that of the piezoelectric region if one touches it (E and D live there, and a
    ceramic's tension is what limits it), else of the region with the larger tag. Built on rank 0 from the
    mesh's cells (vertex indices) and their region tags."""

    def __init__(self, topology: np.ndarray, region_of_cell: np.ndarray, n_nodes: int, piezoelectric_tags):
        n_per_cell = topology.shape[1]
        tags = np.repeat(np.asarray(region_of_cell, dtype=np.int64), n_per_cell)
        key = tags * n_nodes + np.asarray(topology, dtype=np.int64).ravel()
        pairs, self.cell_pair = np.unique(key, return_inverse=True)
        self.pair_region, self.pair_vertex = pairs // n_nodes, pairs % n_nodes
        self.counts = np.bincount(self.cell_pair, minlength=pairs.size)
        priority = self.pair_region + np.isin(self.pair_region, list(piezoelectric_tags)) * (self.pair_region.max() + 1)
        order = np.lexsort((priority, self.pair_vertex))
        self.vertex_pair = order[np.r_[np.diff(self.pair_vertex[order]) != 0, True]]
        if self.vertex_pair.size != n_nodes:
            raise RuntimeError("a mesh vertex belongs to no cell")

    @property
    def size(self) -> int:
        return self.pair_region.size

    def average(self, raw: np.ndarray) -> np.ndarray:
        """(pairs, columns) means of cell-vertex values (cells, vertices per cell, columns)."""
        sums = np.zeros((self.size, raw.shape[-1]))
        np.add.at(sums, self.cell_pair, raw.reshape(-1, raw.shape[-1]))
        return sums / self.counts[:, None]

    def at_vertices(self, pair_values: np.ndarray) -> np.ndarray:
        """One value per mesh vertex (the rule above) from (pairs, ...) values."""
        return pair_values[self.vertex_pair]


def region_peaks(values: np.ndarray, pair_region: np.ndarray, regions, values_im: np.ndarray | None = None) -> dict:
    """Peaks per named region from its region-wise averaged vertex values (:class:`RegionAveraging`: (pairs, 18)
    and each pair's region tag): the largest von Mises stress [Pa]; in piezoelectric regions also the largest
    principal stress [Pa] and the largest |E| [V/m]. With ``values_im`` (a harmonic solution) each is the
    maximum over the cycle. Keys :data:`PEAK_KEYS`."""
    if values_im is None:
        return frame_region_peaks(values[None], pair_region, regions)[0]
    out = {}
    for region in regions:
        mask = pair_region == region.tag
        if not mask.any():
            continue
        re, im = values[mask], values_im[mask]
        T_re = re[:, RAW["stress"]]
        peaks = {"von_mises_Pa": float(von_mises_cycle_max(T_re, im[:, RAW["stress"]]).max())}
        if region.e is not None:
            E_re = re[:, RAW["electric_field"]]
            peaks["max_principal_stress_Pa"] = float(largest_principal_cycle_max(T_re, im[:, RAW["stress"]]).max())
            peaks["electric_field_V_per_m"] = float(norm_cycle_max(E_re, im[:, RAW["electric_field"]]).max())
        out[region.name] = peaks
    return out


def raw_columns(names, electric: bool) -> tuple[np.ndarray, dict]:
    """The raw columns (of the 18: strain, stress, E, D) the derived fields ``names`` and the peaks need (stress;
    E with a piezoelectric region, ``electric``), and where each block is among them: (indices into the 18,
    {block: slice}) for :func:`node_fields` and :func:`frame_region_peaks`' ``columns``."""
    blocks = {"stress"} | ({"electric_field"} if electric else set())
    blocks |= {n if n in RAW else "stress" for n in names}
    chosen = [b for b in RAW if b in blocks]           # in RAW's order
    indices = np.concatenate([np.arange(RAW[b].start, RAW[b].stop) for b in chosen])
    local, start = {}, 0
    for b in chosen:
        width = RAW[b].stop - RAW[b].start
        local[b] = slice(start, start + width)
        start += width
    return indices, local


def _rows_of(pair_region: np.ndarray, tag: int):
    """The pairs of region ``tag``: a slice when they are consecutive (a view, no copy), else their indices."""
    rows = np.flatnonzero(pair_region == tag)
    if rows.size and rows[-1] - rows[0] + 1 == rows.size:
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return rows


def frame_region_peaks(values: np.ndarray | None, pair_region: np.ndarray, regions, columns: dict = RAW,
                       known: dict | None = None) -> list[dict]:
    """:func:`region_peaks` of each of a batch of real frames, (frames, pairs, 18) region-wise averaged values,
    computed for all the frames at once (the field output's batches). ``columns``: where stress and E are in the
    last axis (:func:`raw_columns`); ``known``: the quantities whose maxima the peaks are, at every pair (frames,
    pairs), by peak key (:data:`PEAK_KEYS`: the von Mises stress, the largest principal stress, |E|), when the
    caller formed them already (``values`` may then be None)."""
    known = known or {}
    frames = next(iter(known.values())).shape[0] if values is None else values.shape[0]
    out: list[dict] = [{} for _ in range(frames)]
    for region in regions:
        rows = _rows_of(pair_region, region.tag)
        if isinstance(rows, np.ndarray) and not rows.size:
            continue
        keys = PEAK_KEYS if region.e is not None else PEAK_KEYS[:1]
        peaks = {}
        for key in keys:
            if key in known:
                at_pairs = known[key][:, rows]
            elif key == "electric_field_V_per_m":
                at_pairs = np.linalg.norm(values[:, rows][..., columns["electric_field"]], axis=-1)
            else:
                T = values[:, rows][..., columns["stress"]]
                at_pairs = von_mises(T) if key == "von_mises_Pa" else principal_stresses(T)[..., 0]
            peaks[key] = at_pairs.max(axis=1).tolist()
        for k, frame in enumerate(out):
            frame[region.name] = {key: v[k] for key, v in peaks.items()}
    return out


def merge_peaks(into: dict, peaks: dict) -> dict:
    """Running maxima of :func:`region_peaks` results (a transient's peaks over its frames)."""
    for name, values in peaks.items():
        mine = into.setdefault(name, {})
        for key, value in values.items():
            mine[key] = max(mine.get(key, value), value)
    return into
