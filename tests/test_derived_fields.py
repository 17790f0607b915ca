"""Derived fields (app/fe/derived.py, docs/fields.md) against closed forms.

* Lamé's thick-walled cylinder under internal pressure p, plane strain (u_z = 0 on both ends), steel, in the
  axisymmetric model and in 3D (a quarter of the tube with symmetry planes): at the bore r = a
  sigma_rr = -p, sigma_tt = p (b^2 + a^2) / (b^2 - a^2), sigma_zz = 2 nu p a^2 / (b^2 - a^2) (Timoshenko &
  Goodier, Theory of Elasticity, sec. 28), and the von Mises stress of those three. Three meshes halving h,
  degree-2 displacements; the averaged vertex values of the derived-field code at the bore vertices.
* A PZT-4 bar (IEEE Std 176 constants of the material library, tests/ieee176.py) with electrodes on its ends
  under a static voltage V (the harmonic solver at 0 Hz): the field E3 = -V/L, and the stress T3 of the
  constitutive law: blocked (every face held) T3 = -e33 E3; ends held axially, sides free T3 = -(e33 - 2 c13
  e31 / (c11 + c12)) E3 (the lateral strain S1 = S2 = e31 E3 / (c11 + c12) that makes T1 = T2 = 0).

The static Lamé solve is the model's own stiffness form with a pressure load, assembled here: the project
has no static mechanical load, and the check is of the derived fields, not of a solver.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem.petsc import apply_lifting, assemble_matrix, assemble_vector, set_bc
from ieee176 import blocked_stress_33, observed_order
from mpi4py import MPI
from petsc4py import PETSc

from app.case.schema import DerivedField, load_case
from app.exports import VertexFields
from app.fe import derived
from app.fe.model import build_model
from forms.kinematics import volume_weight
from geometry.meshdata import MeshData

ROOT = Path(__file__).resolve().parents[1]
A_M, B_M, H_M = 0.01, 0.02, 0.002       # bore and outer radius, axial length [m]
PRESSURE_PA = 100e6


def test_derived_names_agree_with_the_schema():
    """The case key's values (app/case/schema.py DerivedField) are the derived fields app/fe/derived.py writes
    (the convention of docs/fields.md)."""
    assert set(DerivedField.__args__) == set(derived.DERIVED_FIELDS)
    assert set(derived.DEFAULT_DERIVED) <= set(derived.DERIVED_FIELDS)


def test_invariants_against_hand_values():
    """Reference: hand values. Uniaxial 100 Pa: von Mises 100 Pa; pure shear tau: von Mises sqrt(3) tau, principal
    (tau, 0, -tau). Harmonic T_re cos - T_im sin with T_re = uniaxial s, T_im = shear s: the von Mises squared is
    s^2 (cos^2 + 3 sin^2), cycle maximum sqrt(3) s; the largest principal is s/2 cos + s sqrt(cos^2/4 + sin^2),
    whose maximum over theta is found here by dense sampling (10^5 phases, error < 1e-9 relative). A von Mises
    of the amplitude tensor sqrt(|re|^2 + |im|^2) would give 2 s and fail."""
    uniaxial = np.array([100.0, 0, 0, 0, 0, 0])
    shear = np.array([0, 0, 0, 0, 0, 50.0])
    assert derived.von_mises(uniaxial) == pytest.approx(100.0, rel=1e-14)
    assert derived.von_mises(shear) == pytest.approx(50.0 * math.sqrt(3), rel=1e-14)
    assert derived.principal_stresses(shear) == pytest.approx([50.0, 0.0, -50.0], abs=1e-12)
    s = 10.0
    re, im = np.array([[s, 0, 0, 0, 0, 0]]), np.array([[0, 0, 0, 0, 0, s]])
    assert derived.von_mises_cycle_max(re, im)[0] == pytest.approx(math.sqrt(3) * s, rel=1e-14)
    theta = np.linspace(0, 2 * np.pi, 100001)
    exact = np.max(0.5 * s * np.cos(theta) + s * np.sqrt(0.25 * np.cos(theta) ** 2 + np.sin(theta) ** 2))
    # sampled at 72 phases and refined by a parabola: the refined vertex is within 1e-5 of the maximum here
    assert derived.largest_principal_cycle_max(re, im)[0] == pytest.approx(exact, rel=1e-5)
    assert derived.largest_principal_cycle_max(re, im)[0] <= exact * (1 + 1e-12)


# ------------------------------------------------------------------------------------------------ Lame
def _lame_exact(nu: float) -> dict:
    k = A_M**2 / (B_M**2 - A_M**2)
    rr, tt, zz = -PRESSURE_PA, PRESSURE_PA * (B_M**2 + A_M**2) / (B_M**2 - A_M**2), 2 * nu * PRESSURE_PA * k
    vm = math.sqrt(0.5 * ((rr - tt) ** 2 + (tt - zz) ** 2 + (zz - rr) ** 2))
    return {"rr": rr, "tt": tt, "vm": vm}


def _tube_mesh(comm, kind: str, n_r: int) -> MeshData:
    """Structured mesh of the tube wall: (r, z) rectangle [a, b] x [0, H] (axisymmetric), or the quarter tube
    0 <= theta <= pi/2 mapped from a box (3D; theta divisions 3 n_r so the polygonal bore's chord error,
    1 - cos(dtheta / 2), stays below 2e-4 at n_r = 4). Cell group 1 "steel"; facet groups inner, outer, bottom,
    top, and in 3D theta0 (y = 0) and theta90 (x = 0)."""
    if kind == "axisymmetric":
        mesh = dmesh.create_rectangle(comm, [[A_M, 0.0], [B_M, H_M]], [n_r, 1], dmesh.CellType.triangle)
        radius = lambda x: x[0]  # noqa: E731
        axial = lambda x: x[1]  # noqa: E731
    else:
        n_t = 3 * n_r
        mesh = dmesh.create_box(comm, [[A_M, 0.0, 0.0], [B_M, 0.5 * np.pi, H_M]], [n_r, n_t, 1],
                                dmesh.CellType.tetrahedron)
        x = mesh.geometry.x
        r, t = x[:, 0].copy(), x[:, 1].copy()
        x[:, 0], x[:, 1] = r * np.cos(t), r * np.sin(t)
        radius = lambda x: np.hypot(x[0], x[1])  # noqa: E731
        axial = lambda x: x[2]  # noqa: E731
    tdim = mesh.topology.dim
    tol = 1e-9
    groups = {"inner": lambda x: np.isclose(radius(x), A_M, atol=tol * 10),
              "outer": lambda x: np.isclose(radius(x), B_M, atol=tol * 10),
              "bottom": lambda x: np.isclose(axial(x), 0.0, atol=tol),
              "top": lambda x: np.isclose(axial(x), H_M, atol=tol)}
    if kind == "3d":
        groups["theta0"] = lambda x: np.isclose(x[1], 0.0, atol=tol)
        groups["theta90"] = lambda x: np.isclose(x[0], 0.0, atol=tol)
    indices, values, names = [], [], {}
    for tag, (name, where) in enumerate(groups.items(), start=1):
        facets = dmesh.locate_entities_boundary(mesh, tdim - 1, where)
        indices.append(facets)
        values.append(np.full(facets.size, tag, dtype=np.int32))
        names[name] = tag
    indices, values = np.concatenate(indices), np.concatenate(values)
    order = np.argsort(indices, kind="stable")
    facet_tags = dmesh.meshtags(mesh, tdim - 1, indices[order].astype(np.int32), values[order])
    n_cells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
    cell_tags = dmesh.meshtags(mesh, tdim, np.arange(n_cells, dtype=np.int32), np.ones(n_cells, dtype=np.int32))
    return MeshData(mesh, cell_tags, facet_tags, {"steel": 1}, names)


def _tube_case(tmp_path: Path, kind: str):
    supports = '{ facets = ["bottom", "top"], components = ["z"] }'
    if kind == "3d":
        supports += ', { facets = ["theta0"], components = ["y"] }, { facets = ["theta90"], components = ["x"] }'
    text = f"""
tier = "fe"
analyses = ["modal"]
supports = [{supports}]
[geometry]
model = "{kind}"
builder = "ring"
degree = 2
parameters = {{ mean_radius_m = {0.5 * (A_M + B_M)}, wall_thickness_m = {B_M - A_M}, height_m = {H_M} }}
[materials.steel]
library = "structural-steel"
[[regions]]
cells = "steel"
material = "steel"
[modal]
target_frequency_Hz = 1e5
[output]
derived = ["stress", "von_mises"]
"""
    path = Path(MPI.COMM_WORLD.bcast(str(tmp_path / f"lame-{kind}.toml"), root=0))   # each rank has its tmp_path
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.barrier()
    return load_case(path)


def _solve_pressure(model) -> PETSc.Vec:
    """K w = f: the model's stiffness form (supports and the steel's grounded potential held) with the
    pressure p on the bore, f = -p int n . v dA (n the outward normal, so the load pushes the wall out)."""
    W = model.W
    v, _ = ufl.TestFunctions(W)
    md = model.mesh_data
    ds = ufl.Measure("ds", domain=model.mesh, subdomain_data=md.facet_tags)
    n = ufl.FacetNormal(model.mesh)
    weight = volume_weight(model.mesh, model.form_kind)
    load = -PRESSURE_PA * ufl.dot(n, v) * weight * ds(md.facet_names["inner"])
    zero = fem.Function(W)
    bcs = [fem.dirichletbc(zero, np.unique(np.concatenate([model.support_dofs, model.grounded_dofs])))]
    a, L = fem.form(model.stiffness), fem.form(load)
    A = assemble_matrix(a, bcs=bcs)
    A.assemble()
    b = assemble_vector(L)
    apply_lifting(b, [a], [bcs])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    set_bc(b, bcs)
    ksp = PETSc.KSP().create(model.comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    x = A.createVecRight()
    ksp.solve(b, x)
    assert ksp.getConvergedReason() > 0
    ksp.destroy()
    A.destroy()
    b.destroy()
    return x


def _bore_errors(tmp_path: Path, kind: str, n_r: int) -> dict:
    """Largest relative errors of sigma_rr, sigma_tt and von Mises over the bore vertices (every rank)."""
    comm = MPI.COMM_WORLD
    case = _tube_case(tmp_path, kind)
    model = build_model(case, comm, mesh_data=_tube_mesh(comm, kind, n_r))
    x = _solve_pressure(model)
    vertex = VertexFields(model, case.output.derived)
    raw = vertex.sample_derived(x)
    errors = None
    if comm.rank == 0:
        c = np.asarray(model.regions[0].c.value)
        nu = c[0, 1] / (c[0, 0] + c[0, 1])
        exact = _lame_exact(nu)
        fields = derived.node_fields(vertex.vertex_average(raw), ["stress", "von_mises"])
        xyz = vertex.mesh_arrays["geometry"]
        radius = xyz[:, 0] if kind == "axisymmetric" else np.hypot(xyz[:, 0], xyz[:, 1])
        bore = np.isclose(radius, A_M, rtol=1e-9)
        T = fields["stress_Pa"][bore]
        if kind == "axisymmetric":      # model axes 1 = r, 2 = theta
            rr, tt = T[:, 0], T[:, 1]
        else:
            tensor = derived.voigt_tensor(T)
            e_r = np.column_stack([xyz[bore, 0], xyz[bore, 1], np.zeros(bore.sum())]) / A_M
            e_t = np.column_stack([-e_r[:, 1], e_r[:, 0], np.zeros(bore.sum())])
            rr = np.einsum("ni,nij,nj->n", e_r, tensor, e_r)
            tt = np.einsum("ni,nij,nj->n", e_t, tensor, e_t)
        vm = fields["von_mises_Pa"][bore]
        errors = {"rr": float(np.max(np.abs(rr / exact["rr"] - 1))), "tt": float(np.max(np.abs(tt / exact["tt"] - 1))),
                  "vm": float(np.max(np.abs(vm / exact["vm"] - 1))), "vertices": int(bore.sum())}
    x.destroy()
    return comm.bcast(errors, root=0)


LAME_MESHES = {"axisymmetric": (4, 8, 16), "3d": (4, 8, 16)}


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["axisymmetric", "3d"])
def test_lame_cylinder_bore_stresses(tmp_path, kind):
    """Lamé cylinder (reference: the closed form above): sigma_rr, sigma_tt and von Mises at the bore within 1 %
    on the finest of three meshes, and the observed order of the largest error sensible for degree-2
    displacements (stress error O(h^2): the order must exceed 1.5; measured on 2026-11-26, see the report in
    docs/fields.md). The tolerance 1 % is the issue's; measured finest errors are printed."""
    errors = [_bore_errors(tmp_path, kind, n) for n in LAME_MESHES[kind]]
    h = [1.0 / n for n in LAME_MESHES[kind]]
    worst = [max(e["rr"], e["tt"], e["vm"]) for e in errors]
    order = observed_order(h, worst)
    print(f"Lame {kind}: n_r {LAME_MESHES[kind]} worst relative bore errors {worst} observed order {order:.2f}; "
          f"finest {errors[-1]}")
    finest = errors[-1]
    assert finest["vertices"] > 0
    assert finest["rr"] < 0.01 and finest["tt"] < 0.01 and finest["vm"] < 0.01, finest
    assert worst[0] > worst[1] > worst[2], worst
    assert order > 1.5, (order, worst)


# ------------------------------------------------------------------------------------------------ PZT bar
@pytest.mark.mpi
@pytest.mark.parametrize("kind,lateral", [("axisymmetric", "blocked"), ("axisymmetric", "free"), ("3d", "blocked")])
def test_pzt_bar_blocked_stress(kind, lateral):
    """PZT-4 bar, ends held, under 100 V (reference: the uniform states of tests/ieee176.blocked_stress_33 from
    the library's IEEE 176 constants). Both states are linear in the coordinates, so degree-2 elements hold
    them exactly: E3 = -V/L and T3 within 1 % (the issue's tolerance; measured error ~1e-12, solver precision)
    at every vertex of the averaged field."""
    from app.fe.operators import assemble_operators
    from app.harmonic import HarmonicSolver

    comm = MPI.COMM_WORLD
    voltage, length = 100.0, 0.02
    components = ("r", "z") if kind == "axisymmetric" else ("x", "y", "z")
    if lateral == "blocked":
        supports = f'[{{ facets = ["bottom", "top", "side"], components = {list(components)} }}]'.replace("'", '"')
    else:
        supports = '[{ facets = ["bottom", "top"], components = ["z"] }]'
    case = load_case(ROOT / "cases" / "validation" / f"pzt4-bar-{kind}.toml",
                     ['analyses=["harmonic"]', "harmonic.f_start_Hz=1.0", "harmonic.f_stop_Hz=2.0",
                      f"supports={supports}", f"harmonic.voltage_V={voltage}",
                      'output.derived=["stress", "electric_field"]',
                      f"geometry.parameters.length_m={length}", "geometry.parameters.axial_divisions=4"])
    model = build_model(case, comm)
    ops = assemble_operators(model)
    solver = HarmonicSolver(model, ops, voltage)
    solver.solve(0.0)
    x_re, _ = solver.full_solution()
    vertex = VertexFields(model, case.output.derived)
    raw = vertex.sample_derived(x_re)
    errors = None
    if comm.rank == 0:
        c, e, eps = case.materials["pzt4"].tensors()
        E3 = -voltage / length                   # hot electrode (top, z = L) at +V, ground at z = 0
        T3 = blocked_stress_33(c, e, E3, lateral)
        fields = derived.node_fields(vertex.vertex_average(raw), ["stress", "electric_field"])
        errors = {"E3": float(np.max(np.abs(fields["electric_field_V_per_m"][:, 2] / E3 - 1))),
                  "T3": float(np.max(np.abs(fields["stress_Pa"][:, 2] / T3 - 1))), "T3_expected_Pa": T3}
    errors = comm.bcast(errors, root=0)
    print(f"PZT-4 bar {kind} {lateral}: {errors}")
    solver.destroy()
    ops.destroy()
    assert errors["E3"] < 0.01 and errors["T3"] < 0.01, errors


# ------------------------------------------------------------------------------------------------ the files
TRANSDUCER_COARSE = ["output.plots=false", "geometry.parameters.mesh_size_m=0.004",
                     "geometry.parameters.ceramic_mesh_size_m=0.0025", 'analyses=["modal", "harmonic"]',
                     "harmonic.n_points=5", "harmonic.refine_extrema=false",
                     'output.derived=["strain", "stress", "von_mises", "principal_stress", "electric_field", '
                     '"electric_displacement"]']


def test_transducer_files_carry_derived_fields_and_region_names(tmp_path):
    """The convention of docs/fields.md on the drill transducer (coarse): the harmonic response file opens in meshio
    with the derived fields (units in their names), the Domain names the regions as summary.json does and a cell
    array per region marks its cells, and the
    maxima over the cycle agree with a brute-force maximum over 3600 phases of the file's own real and imaginary
    stress (reference: direct sampling; its error (1 - cos(0.05 deg)) < 4e-7 relative, tolerance 1e-5). Near
    resonance the response is almost a standing wave (re and im stresses nearly parallel), where the exact
    cycle maximum and the amplitude-tensor value nearly coincide: that formula is told apart by
    test_invariants_against_hand_values; here the check is that the file's maxima are those of its own re and
    im parts (a maximum from the real part alone, or of another field, fails)."""
    import json
    import xml.etree.ElementTree as ET

    import meshio
    from conftest import CASES, run_cli

    out = tmp_path / "out"
    proc = run_cli("run", str(CASES / "usdc-transducer.toml"), "--out", str(out), "--quiet",
                   *[a for o in TRANSDUCER_COARSE for a in ("--set", o)])
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    names = summary["regions"]
    assert sorted(names.values()) == ["back", "bolt", "horn", "piezo_0", "piezo_1", "piezo_2", "piezo_3"]
    info = ET.parse(out / "harmonic_fields.xdmf").getroot().find("Domain/Information")
    assert info.get("Name") == "region_names"
    assert dict(item.split(": ") for item in info.get("Value").split("; ")) == names
    with meshio.xdmf.TimeSeriesReader(str(out / "harmonic_fields.xdmf")) as reader:
        reader.read_points_cells()
        frequency, point_data, cell_data = reader.read_data(0)
    assert frequency == pytest.approx(summary["results"]["harmonic"]["field_frequency_Hz"])
    # the region names as cell arrays, one per region (1 in its cells), as ParaView shows them
    assert set(cell_data) == {"region", *(f"region: {name}" for name in names.values())}
    for tag, name in names.items():
        np.testing.assert_array_equal(cell_data[f"region: {name}"][0], cell_data["region"][0] == int(tag))
    expected = {"displacement", "potential", "displacement_im", "potential_im", "von_mises_cycle_max_Pa",
                "max_principal_stress_cycle_max_Pa"}
    for base in ("strain", "stress_{}_Pa", "electric_field_{}_V_per_m", "electric_displacement_{}_C_per_m2"):
        expected |= {base.format(p) if "{}" in base else f"{base}_{p}" for p in ("re", "im")}
    assert set(point_data) == expected
    theta = np.linspace(0, 2 * np.pi, 3600, endpoint=False)[:, None, None]
    T = point_data["stress_re_Pa"][None] * np.cos(theta) - point_data["stress_im_Pa"][None] * np.sin(theta)
    sampled_vm = derived.von_mises(T).max(axis=0)
    sampled_principal = derived.principal_stresses(T)[..., 0].max(axis=0)
    scale = sampled_vm.max()
    assert np.abs(point_data["von_mises_cycle_max_Pa"] - sampled_vm).max() < 1e-5 * scale
    assert np.abs(point_data["max_principal_stress_cycle_max_Pa"] - sampled_principal).max() < 1e-5 * scale
    peaks = summary["results"]["harmonic"]["field_peaks"]
    assert set(peaks) == set(names.values())
    assert set(peaks["piezo_0"]) == set(derived.PEAK_KEYS) and set(peaks["horn"]) == {"von_mises_Pa"}


def test_principal_stresses_agree_with_lapack_near_repeated_values():
    """The closed-form principal stresses (app.fe.derived.principal_stresses, the field output's) against LAPACK's
    eigvalsh on rotated tensors whose two principal stresses differ by 1e-1 ... 1e-13 of the largest, and on random
    tensors over 12 decades: within 1e-12 of the tensor's largest component. Why 1e-12: LAPACK's own error is a few
    machine epsilons of |T|; the closed form alone loses up to sqrt(epsilon) |T| = 1.5e-8 near repeated values (the
    cases it hands to eigvalsh), so a threshold set wrong fails here."""
    rng = np.random.default_rng(3)
    rotation, _ = np.linalg.qr(rng.standard_normal((1300, 3, 3)))
    gaps = np.repeat(10.0 ** -np.arange(1, 14), 100)
    diagonal = np.zeros((1300, 3, 3))
    diagonal[:, 0, 0], diagonal[:, 1, 1], diagonal[:, 2, 2] = 1e8, 1e8 * (1 - gaps), rng.uniform(-2e8, 2e8, 1300)
    M = rotation @ diagonal @ rotation.transpose(0, 2, 1)
    near = np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], M[:, 1, 2], M[:, 0, 2], M[:, 0, 1]], axis=-1)
    spread = rng.standard_normal((20000, 6)) * 10.0 ** rng.uniform(-3, 9, (20000, 1))
    for T in (near, spread, np.array([[1e8, 0, 0, 0, 0, 0], [0.0] * 6])):
        reference = np.linalg.eigvalsh(derived.voigt_tensor(T))[..., ::-1]
        error = np.abs(derived.principal_stresses(T) - reference) / np.maximum(np.abs(T).max(axis=-1), 1e-300)[:, None]
        assert error.max() <= 1e-12
    # one shear zero everywhere, given as the float 0.0 (the modal field output's components): the general closed
    # form on the other five, the same values as the tensors with that column zero
    T = near.copy()
    T[:, 3] = 0.0
    parts = [0.0 if i == 3 else T[:, i] for i in range(6)]
    np.testing.assert_array_equal(np.stack(derived.principal_of_parts(parts), axis=-1), derived.principal_stresses(T))


@pytest.mark.parametrize("normal", [0, 1, 2])
def test_principal_stresses_of_plane_tensors_agree_with_lapack(normal):
    """The closed form of app.fe.derived.principal_of_parts for tensors whose two shears out of one plane are zero
    everywhere (a model of revolution's or a plane model's: one principal direction normal to the plane, the
    in-plane pair from a 2 x 2 problem), for each of the three planes: against LAPACK's eigvalsh, within 1e-12 of
    the tensor's largest component (LAPACK's own error is a few machine epsilons of |T|), on tensors whose normal
    stress equals an in-plane principal one (the axis of a model of revolution, sigma_rr = sigma_thetatheta),
    nearly equals it (1e-1 ... 1e-13), lies above, between and below the pair, and on zero tensors; and given the
    zero shears as the float 0.0 (the modal field output's components zero everywhere), the same values."""
    rng = np.random.default_rng(5)
    n = 1400
    plane = [i for i in range(3) if i != normal]
    shear = {2: 5, 1: 4, 0: 3}[normal]              # xy, xz, yz: the plane's own shear
    angle = rng.uniform(0, 2 * np.pi, n)
    s_hi, s_lo = rng.uniform(-1e8, 1e8, n), rng.uniform(-1e8, 1e8, n)
    s_hi, s_lo = np.maximum(s_hi, s_lo), np.minimum(s_hi, s_lo)
    gaps = np.repeat(np.r_[0.0, 10.0 ** -np.arange(1, 14)], 100)
    normal_stress = np.concatenate([s_hi[:700] * (1 - gaps[:700]), s_lo[700:] * (1 + gaps[700:])])
    normal_stress[::7] = rng.uniform(-3e8, 3e8, normal_stress[::7].size)      # anywhere: above, between, below
    c, s = np.cos(angle), np.sin(angle)
    T = np.zeros((n, 6))
    T[:, plane[0]] = s_hi * c * c + s_lo * s * s
    T[:, plane[1]] = s_hi * s * s + s_lo * c * c
    T[:, shear] = (s_hi - s_lo) * s * c
    T[:, normal] = normal_stress
    T[-5:] = 0.0
    reference = np.linalg.eigvalsh(derived.voigt_tensor(T))[..., ::-1]
    scale = np.maximum(np.abs(T).max(axis=-1), 1e-300)[:, None]
    assert (np.abs(derived.principal_stresses(T) - reference) / scale).max() <= 1e-12
    parts = [T[:, i] if i in (plane[0], plane[1], shear, normal) else 0.0 for i in range(6)]
    np.testing.assert_array_equal(np.stack(derived.principal_of_parts(parts), axis=-1), derived.principal_stresses(T))
