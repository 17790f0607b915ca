"""Friction through a rotating contact (app/transient/contact.py SurfaceContact with rotation axes):
an elastic strip (plane strain) pressed on a rigid disc that spins about its own axis. The disc
is a body of revolution, so its spin leaves the gap alone and enters friction only: the contact
slips at omega R, the friction force is mu_d times the normal force along the disc's surface
velocity, and its torque on the disc is -R mu_d N. A free disc spins down at the rate its
torque says (J omega' = torque), with Newton converging on the coupled tangent (no cut-back)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from app.case.schema import load_case
from app.errors import CaseError
from app.runner import run_transient_analysis

RADIUS_M, MU_D, INERTIA_KG_M2 = 0.01, 0.25, 1e-4

CASE = """
title = "strip on a spinning disc"
tier = "fe"
analyses = ["transient"]

[geometry]
model = "plane_strain"
builder = "bar"
parameters = {{ length_m = 0.01, width_m = 0.002, axial_divisions = 5, lateral_divisions = 2 }}

[materials.pzt4]
library = "PZT-4"

[[regions]]
cells = "piezo"
material = "pzt4"
poling = "+z"

[electrodes.ground]
facets = ["bottom"]
kind = "ground"

[output]
fields = false
plots = false

[transient]
end_time_s = 4e-5
output_interval_s = 4e-5
initial_state = "rest"

[transient.steps]
open_s = 2e-7
closed_s = 2e-7
change_s = 2e-7

[transient.loads]
fe_force_N = [0.0, -1000.0]

[[transient.bodies]]
name = "disc"
position_m = [0.001, -{radius}]
fixed = true

[[transient.bodies.rotations]]
axis = "plane"
{rotation}

[[transient.contacts]]
name = "strip_disc"
kind = "surface"
facets = "bottom"
body = "disc"
shape = "sphere"
radius_m = {radius}
normal = [0.0, 1.0]
stiffness = 1e13
damping = 1e6

[transient.contacts.friction]
mu_dynamic = {mu}
static_ratio = 1.5
decay_s_per_m = 100.0
"""


def _run(tmp_path, name, rotation, fixed=True):
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / name if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        folder.mkdir()
        text = CASE.format(radius=RADIUS_M, mu=MU_D, rotation=rotation)
        if not fixed:       # the disc's centre is held, its rotation free
            text = text.replace("fixed = true", "mass_kg = 1.0\nfree_axes = [false, false]")
        (folder / "case.toml").write_text(text)
    comm.barrier()
    case = load_case(folder / "case.toml")
    results = run(case, folder / "out", comm, lambda *args: None)
    with h5py.File(folder / "out" / "transient.h5", "r") as f:
        data = {k: f[k][()] for k in f}
    return data, results


def assert_kinetic_torque(force, torque):
    pressure = np.linalg.norm(force, axis=1) / np.sqrt(1 + MU_D**2)
    np.testing.assert_allclose(-torque / RADIUS_M, MU_D * pressure, rtol=1e-3)


@pytest.mark.mpi
def test_spinning_disc_drags_the_strip_at_kinetic_friction(tmp_path):
    omega = 100.0                                  # surface speed 1 m/s at the top: along -x
    data, results = _run(tmp_path, "spin", f'motion = "constant_rate"\nrate_rad_per_s = {omega}')
    closed = data["strip_disc_closed"] > 0
    assert closed.sum() > 100 and results["cutbacks"] == 0
    force = data["strip_disc_force_N"][closed]          # on the disc
    torque = data["strip_disc_torque_N_m"][closed, 0]
    normal = -force[:, 1]
    assert normal.min() > 0
    # the strip is dragged along the disc's surface velocity (-x): the disc feels +x. The contact
    # patch (~0.05 mm) is sampled by a few quadrature points of 1 mm facets, off the top of the
    # disc by up to ~0.1 mm: their normals tilt by up to 1e-2 rad, which moves F_x / F_y by a few %.
    np.testing.assert_allclose(force[:, 0] / normal, MU_D, rtol=0.1)
    # Exact on a circle whatever the tilt: the pressure passes through the centre, so the torque
    # is -R times the friction, and |F| = sqrt(1 + mu^2) int p up to the tilt squared (1e-4).
    assert_kinetic_torque(force, torque)
    np.testing.assert_allclose(data["disc_angular_velocity_rad_per_s"][:, 0], omega, rtol=1e-10)   # prescribed


@pytest.mark.mpi
def test_free_disc_spins_down_by_its_friction_torque(tmp_path):
    omega0 = 100.0
    data, results = _run(tmp_path, "free", f"inertia_kg_m2 = {INERTIA_KG_M2}\nrate_rad_per_s = {omega0}",
                         fixed=False)
    assert results["cutbacks"] == 0
    assert results["newton_iterations"] <= 6 * results["steps"]
    omega = data["disc_angular_velocity_rad_per_s"][:, 0]
    torque = data["strip_disc_torque_N_m"][:, 0]
    # angular momentum balance of the scheme: J ((1 - a_m) alpha_{n+1} + a_m alpha_n) = T_n (the
    # torque at the generalised mid-point) and the Newmark velocity update give
    # J (omega_N - omega_0) = sum dt T_n + J dt (gamma - 1 + a_m)(alpha_N - alpha_0): the boundary
    # term vanishes when the contact is open at both ends (the strip bounces off the disc here).
    dt = data["dt_s"]
    closed = data["strip_disc_closed"] > 0
    assert not closed[0] and not closed[-1]
    impulse = np.cumsum(torque * dt)
    assert closed.sum() > 50
    assert np.all(np.diff(omega)[closed[1:]] < 0)          # friction opposes the spin
    assert np.all(torque[~closed] == 0.0)
    assert INERTIA_KG_M2 * (omega[-1] - omega0) == pytest.approx(impulse[-1], rel=1e-8)
    assert_kinetic_torque(data["strip_disc_force_N"][closed], torque[closed])


@pytest.mark.mpi
def test_an_obstacle_that_is_not_a_body_of_revolution_is_refused(tmp_path):
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / "plane" if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        folder.mkdir()
        text = CASE.format(radius=RADIUS_M, mu=MU_D, rotation='motion = "constant_rate"\nrate_rad_per_s = 1.0')
        text = text.replace('shape = "sphere"', 'shape = "plane"')
        (folder / "case.toml").write_text(text)
    comm.barrier()
    with pytest.raises(CaseError) as err:       # when the case is read, for every tier
        load_case(folder / "case.toml")
    assert err.value.key == "transient.contacts[0].normal" and "not a body of revolution" in str(err.value)


@pytest.mark.mpi
def test_node_contact_friction_on_a_spinning_disc(tmp_path):
    """The strip's bottom-centre node on the spinning disc (node kind, Hertz law): the node's
    force is f n + F_t with n fixed, so F_x / F_y is mu(slip) = mu_d exactly while it slips."""
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tmp_path / "node" if comm.rank == 0 else None, root=0)
    if comm.rank == 0:
        folder.mkdir()
        text = CASE.format(radius=RADIUS_M, mu=MU_D, rotation='motion = "constant_rate"\nrate_rad_per_s = 100.0')
        text = text.replace(f'''kind = "surface"
facets = "bottom"
body = "disc"
shape = "sphere"
radius_m = {RADIUS_M}
normal = [0.0, 1.0]
stiffness = 1e13
damping = 1e6''', f'''kind = "node"
node_point = "bottom"
body = "disc"
radius_m = {RADIUS_M}
normal = [0.0, 1.0]
stiffness = 1e10
damping = 10.0''') + '''
[points.bottom]
coordinates_m = [0.001, 0.0]
component = "x"
'''
        assert 'kind = "node"' in text
        (folder / "case.toml").write_text(text)
    comm.barrier()
    results = run(load_case(folder / "case.toml"), folder / "out", comm, lambda *args: None)
    with h5py.File(folder / "out" / "transient.h5", "r") as f:
        force, closed = f["strip_disc_force_N"][()], f["strip_disc_closed"][()] > 0
        drift = f["bottom_displacement_m"][()]
    assert closed.sum() > 50 and results["cutbacks"] == 0
    np.testing.assert_allclose(force[closed, 0] / -force[closed, 1], MU_D, rtol=1e-8)
    assert drift[-1] < 0                         # the node is dragged along the disc's surface (-x)


def run(case, out_dir, comm, log, resume=False):
    """The case's transient analysis through the one run loop (the FE tier's engine), as ``piezodyn run`` does."""
    out_dir = Path(out_dir)
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    return run_transient_analysis(case, out_dir, comm, log, resume)
