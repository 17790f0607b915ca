"""The contact pressure field (``output.contact_pressure``) against Hertz: a rigid sphere pressed into an elastic
half-space, axisymmetric, brought to static equilibrium by the transient solver.

Reference: Hertz (K. L. Johnson, Contact Mechanics, 1985, sec. 4.2) for a rigid sphere of radius R on an
elastic half-space (E, nu) under a normal load F, with E* = E / (1 - nu^2):

    a = (3 F R / (4 E*))^(1/3),   p0 = 3 F / (2 pi a^2),   p(r) = p0 sqrt(1 - r^2 / a^2).

The set-up (:data:`CASE`): a steel block ("structural-steel", E = 200 GPa, nu = 0.3) of radius and height
``block`` x a (40 a = 20 mm), held at its bottom face; its top face (facet group "top") is the surface contact
against a rigid sphere of R = 20 a = 10 mm (a / R = 0.05: the paraboloid of Hertz differs from the sphere by
(a/R)^2 / 4 = 0.06 % of the approach at the contact edge). The sphere is a held body moving down at a constant
speed from first touch to the Hertz approach a^2 / R = 25 um of the design load (3.7 kN, a = 0.5 mm) in 4 steps;
F is the contact force the solver reports at the end, and Hertz is evaluated at that F. The mesh is graded from
h = a / ``elements_across_a`` in a 1.5 a square at the contact to 4 a at the far faces (P2 triangles, the field
written at the vertices: one vertex per h). Static equilibrium: generalized-alpha with rho_inf = 0 at a step of
1 ms, about 300 times the block's longest period (~3 us), so its spectral radius (0 at omega dt -> inf) removes
the dynamic response and each step is a static solve of the penalty contact (its Newton on the active set); the
block's inertia under the constant-speed indentation is zero. 4 or 8 steps give the same p0 and a to 3e-9.

Measured from the field file (``contact_pressure_Pa`` of the last frame of ``transient_fields.xdmf``, along the
top face): p0 = the pressure at the axis vertex; a = the zero of the least-squares line of p^2 against r^2 through
the vertices with p >= p0 / 2 (Hertz: p^2 is linear in r^2; r <= 0.87 a, which leaves out the edge element, where
the field, a vertex's average of the law over the facets round it, spreads the square-root fall over an element).

Errors against Hertz at the reported F (``python tests/test_contact_hertz.py``, 2026-11-26):

| elements across a | p0 | a |
|---|---|---|
| 10 | -0.28 % | -0.55 % |
| 20 | -0.16 % | -0.18 % |
| 40 | -0.13 % | -0.08 % |

What the reference leaves out, measured on the 10-element mesh:
- the finite block: 80 a instead of 40 a moves p0 and a by less than 0.01 % (it changes the load of the approach,
  3723 N against 3762 N, not Hertz's relations between F, a and p0);
- the penalty's own compliance: k = 1e17 Pa/m gives a penetration p0 / k = 0.07 um at the centre, 0.28 % of the
  Hertz approach a^2 / R = 25 um; k x 10 moves p0 by +0.23 % and a by +0.02 %;
- the field's averaging over the facets round a vertex: for Hertz's smooth profile -0.15 % at the axis vertex
  with 10 elements (p falls as 1 - r^2 / (2 a^2), the hat function times r weights r^2 by 0.3 h^2); the law's
  pointwise value at that vertex was measured lower still (-0.50 %, the penalty pressure varies between the P2
  nodes), so the averaged field is the better estimate of p0;
- the rest is discretisation (it falls with h: a -0.55 %, -0.18 %, -0.08 %).
The CI check (10 elements) asks 1 %: the 0.55 % measured plus the penalty's 0.23 %, with room for a different
gmsh. It fails on a penalty 10x softer (1e16 Pa/m, penetration 2.8 % of the approach: measured p0 -2.4 %) and on
a pressure field written 2 % low (measured p0 -2.3 %). The issue asks 5 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from test_transient_checkpoint import frame_group

from app.case.schema import load_case
from app.runner import run_transient_analysis
from app.transient.fields import read_frames
from geometry.meshdata import GmshSession  # imported on every rank: it imports dolfinx (PETSc's set-up)

E_PA, NU = 200e9, 0.30              # the library's "structural-steel"
E_STAR_PA = E_PA / (1 - NU**2)       # rigid indenter
A_TARGET_M = 0.5e-3                  # the Hertz contact radius the load is chosen for
SPHERE_RADIUS_M = 20 * A_TARGET_M
LOAD_N = 4 * E_STAR_PA * A_TARGET_M**3 / (3 * SPHERE_RADIUS_M)       # 3663 N
APPROACH_M = A_TARGET_M**2 / SPHERE_RADIUS_M                           # Hertz: 25 um
PENALTY_PA_PER_M = 1e17
STEP_S = 1e-3


def hertz(force_N: float, radius_m: float = SPHERE_RADIUS_M) -> tuple[float, float]:
    """(contact radius a [m], peak pressure p0 [Pa]) of a rigid sphere on an elastic half-space."""
    a = (3 * force_N * radius_m / (4 * E_STAR_PA)) ** (1 / 3)
    return a, 3 * force_N / (2 * math.pi * a**2)


def write_block_mesh(path, elements_across_a: int, block: float) -> None:
    """An axisymmetric block (r, z) in [0, block a] x [-block a, 0], graded from a / elements_across_a within
    1.5 a of the contact centre to 4 a far away. Cell group "block"; facet groups "top", "bottom", "outer"."""
    import gmsh

    size = block * A_TARGET_M
    fine = A_TARGET_M / elements_across_a
    with GmshSession(MPI.COMM_SELF, "hertz_block"):
        occ = gmsh.model.occ
        surface = occ.addRectangle(0.0, -size, 0.0, size, size)
        occ.synchronize()
        groups = {"top": [], "bottom": [], "outer": []}
        for _, curve in gmsh.model.getBoundary([(2, surface)], oriented=False):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, curve)
            if abs(y1 - y0) < 1e-3 * size:
                groups["top" if y0 > -0.5 * size else "bottom"].append(curve)
            elif x0 > 0.5 * size:
                groups["outer"].append(curve)
        gmsh.model.addPhysicalGroup(2, [surface], 1)
        gmsh.model.setPhysicalName(2, 1, "block")
        for tag, (name, curves) in enumerate(groups.items(), start=1):
            gmsh.model.addPhysicalGroup(1, curves, tag)
            gmsh.model.setPhysicalName(1, tag, name)
        field = gmsh.model.mesh.field
        box = field.add("Box")
        field.setNumber(box, "VIn", fine)
        field.setNumber(box, "VOut", 4 * A_TARGET_M)
        field.setNumber(box, "XMin", -1.0)
        field.setNumber(box, "XMax", 1.5 * A_TARGET_M)
        field.setNumber(box, "YMin", -1.5 * A_TARGET_M)
        field.setNumber(box, "YMax", 1.0)
        field.setNumber(box, "Thickness", 3 * size)
        field.setAsBackgroundMesh(box)
        for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(option, 0)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints"):
            gmsh.option.setNumber(option, 1)        # gmsh's defaults, for later meshes


CASE = """
title = "rigid sphere pressed on an elastic half-space (Hertz)"
tier = "fe"
analyses = ["transient"]

[geometry]
model = "axisymmetric"
mesh_file = "block.msh"
degree = 2

[materials.steel]
library = "structural-steel"

[[regions]]
cells = "block"
material = "steel"

[[supports]]
facets = ["bottom"]
components = ["r", "z"]

[damping]
material_quality = false
beta_s = 0.0

[output]
fields = true
plots = false
contact_pressure = true

[transient]
end_time_s = {end_time}
output_interval_s = {end_time}
initial_state = "rest"

[transient.scheme]
kind = "generalized_alpha"
rho_inf = 0.0

[transient.steps]
open_s = {step}
closed_s = {step}
change_s = {step}

[[transient.bodies]]
name = "sphere"
position_m = [0.0, {radius}]
mass_kg = 1e-3
free_axes = [false, false]
velocity_m_per_s = [0.0, -{speed}]

[[transient.contacts]]
name = "indenter"
kind = "surface"
facets = "top"
body = "sphere"
shape = "sphere"
radius_m = {radius}
normal = [0.0, -1.0]
stiffness = {penalty}
"""


def run(folder: Path, elements_across_a: int, block: float = 40.0, penalty: float = PENALTY_PA_PER_M,
        steps: int = 4) -> dict:
    """Press the sphere on the block; returns the measured p0, a, force and the run's summary (all ranks)."""
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
        write_block_mesh(folder / "block.msh", elements_across_a, block)
        (folder / "case.toml").write_text(CASE.format(end_time=steps * STEP_S, step=STEP_S, radius=SPHERE_RADIUS_M,
                                                      speed=APPROACH_M / (steps * STEP_S), penalty=penalty))
    comm.barrier()
    case = load_case(folder / "case.toml")
    results = run_transient_analysis(case, folder / "out", comm, lambda *args: None, False)
    measured = None
    if comm.rank == 0:
        measured = measure(folder / "out")
    measured = comm.bcast(measured, root=0)
    measured["results"] = results
    return measured


def measure(out: Path) -> dict:
    fields = out / "transient_fields"
    with h5py.File(fields / "mesh.h5", "r") as f:
        x = f["mesh/geometry"][()]
    last = len(read_frames(out / "transient_fields.xdmf", ())) - 1
    with frame_group(out, last) as f:
        pressure = f["contact_pressure_Pa"][()]
        units = f.units("contact_pressure_Pa")
    top = np.abs(x[:, 1]) < 1e-12
    r, p = x[top, 0], pressure[top]
    order = np.argsort(r)
    r, p = r[order], p[order]
    p0 = float(p[0])
    fit = p >= 0.5 * p0
    slope, intercept = np.polyfit(r[fit] ** 2, p[fit] ** 2, 1)
    a = math.sqrt(-intercept / slope)
    with h5py.File(out / "transient.h5", "r") as f:
        force = f["indenter_force_N"][()]
        peak = f["indenter_peak_pressure_Pa"][()]
    return {"p0_Pa": p0, "a_m": a, "force_N": float(force[-1, 1]),
            "elements_across_a": int(np.sum((r > 0) & (r <= a))),
            "peak_series_Pa": peak, "units": str(units), "off_surface_max_Pa": float(np.abs(pressure[~top]).max()),
            "r_m": r, "p_Pa": p}


#: the CI tolerance on p0 and a (module docstring: measured 0.28 % and 0.55 % at 10 elements, the penalty 0.23 %)
TOLERANCE = 0.01


@pytest.fixture(scope="module")
def pressed(tmp_path_factory):
    """The sphere pressed on the 10-elements-across-a mesh (about 10 s serially)."""
    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(str(tmp_path_factory.mktemp("hertz")) if comm.rank == 0 else None, root=0))
    return folder, run(folder, 10)


@pytest.mark.mpi
def test_contact_pressure_field_matches_hertz(pressed):
    """p0 and a from the written field against Hertz at the reported load (tolerance: module docstring)."""
    _, m = pressed
    a, p0 = hertz(m["force_N"])
    assert m["elements_across_a"] >= 10                  # vertices in (0, a]
    assert m["p0_Pa"] == pytest.approx(p0, rel=TOLERANCE)
    assert m["a_m"] == pytest.approx(a, rel=TOLERANCE)


@pytest.mark.mpi
def test_contact_pressure_field_carries_the_contact_force(pressed):
    """The documented outputs (docs/contact.md, docs/summary.md): ``contact_pressure_Pa`` [Pa] in the field file,
    zero off the contact surface; its integral over the top face (trapezoid in r, weight 2 pi r) is the
    contact force the solver reports, assembled separately at the facets' quadrature points (measured -0.43 % at
    10 elements: the trapezoid against the field's hat-function weights, over the edge element where p falls as
    sqrt(a - r); 1 % asked, while a field of nodal forces or without the axisymmetric weight is off by orders);
    the run's peak in the summary is the largest of the per-step peaks and the field's p0 (the same state)."""
    folder, m = pressed
    assert m["units"] == "Pa"
    assert m["off_surface_max_Pa"] == 0.0
    total = np.trapz(2 * math.pi * m["r_m"] * m["p_Pa"], m["r_m"])
    assert total == pytest.approx(m["force_N"], rel=0.01)
    summary = m["results"]["contacts"]["indenter"]
    assert summary["max_pressure_Pa"] == pytest.approx(float(np.max(m["peak_series_Pa"])), rel=1e-12)
    assert summary["max_pressure_Pa"] == pytest.approx(m["p0_Pa"], rel=1e-9)   # the peak of the last frame
    assert np.all(np.diff(m["peak_series_Pa"]) > 0)          # pressed deeper at every step
    if MPI.COMM_WORLD.rank == 0:
        xdmf = (folder / "out" / "transient_fields.xdmf").read_text()
        assert xdmf.count('Attribute Name="contact_pressure_Pa"') == 2     # the frames at t = 0 and at the end


@pytest.mark.slow
def test_contact_pressure_converges_to_hertz_on_three_meshes(tmp_path):
    """10, 20 and 40 elements across a: every mesh within the CI tolerance, and the finest within 0.5 % (measured
    p0 -0.13 % and a -0.08 %: what is left is mostly the penalty's 0.2 %, module docstring)."""
    errors = []
    for n in (10, 20, 40):
        m = run(tmp_path / f"n{n}", n)
        a, p0 = hertz(m["force_N"])
        errors.append((m["p0_Pa"] / p0 - 1, m["a_m"] / a - 1))
    errors = np.abs(np.array(errors))
    assert np.all(errors < TOLERANCE)
    assert np.all(errors[-1] < 0.005)
    assert np.all(errors[-1] < errors[0])


if __name__ == "__main__":        # the docstring's table: python tests/test_contact_hertz.py [elements ...]
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as scratch:
        for n in [int(arg) for arg in sys.argv[1:]] or [10, 20, 40]:
            m = run(Path(scratch) / f"n{n}", n)
            a, p0 = hertz(m["force_N"])
            if MPI.COMM_WORLD.rank == 0:
                print(f"{n} elements across a: F = {m['force_N']:.2f} N, p0 {m['p0_Pa'] / p0 - 1:+.2%}, "
                      f"a {m['a_m'] / a - 1:+.2%}")
