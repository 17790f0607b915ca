"""The motor in the FE tier: the rotor seated on the harmonic start (``seat_on``, app/transient/driver.py) with
the faceted band's initial gap excluded (``exclude_initial_gap``, forms/contact.py).

On a very coarse stator (P1, 4 mm / 2 mm elements, 5.8k DOFs) the held rotor starts from the stator's free
harmonic steady state:

* the seating distance is the modal tier's rule, dz0 = -min_i(n_i . u_i) / sin(alpha) over the band nodes (the
  rotor just touches the highest crest; app/reduced/engine.py), found here by the FE contact's secant iteration;
* seated, the rotor starts without an impulse and is not thrown: over three periods it never rises above its
  seat and the contact stays closed (started on the design position instead, it overlaps the crests and its
  first step takes 3.6 N, 3.7 times the preload);
* the FE tier writes the per-site diagnostics of the modal tier under the same names, the wave-frame bins' normal
  force equal to the sites' pressure x area (round-off: the same products summed), the contact's centre near the
  crest (within 45 deg of wave: the rotor rests on the crests).
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import PINNED_MOTOR
from mpi4py import MPI

from app.case.schema import load_case
from app.runner import run_case
from app.transient.driver import build

ALPHA = math.radians(15.0)
TINY_FE = ['tier="fe"', "geometry.degree=1", "geometry.parameters.mesh_size_m=0.004",
           "geometry.parameters.tip_mesh_size_m=0.002", "transient.end_time_s=8.32e-5",     # 3 periods
           'transient.bodies[0].rotations[0].motion="fixed"', "output.fields=false", "output.plots=false"]


def quiet(*args):
    pass


@pytest.fixture(scope="module")
def seated(tmp_path_factory):
    comm = MPI.COMM_WORLD
    case = load_case(PINNED_MOTOR, TINY_FE)
    out = Path(comm.bcast(str(tmp_path_factory.mktemp("seated")), root=0))      # one directory on every rank
    results = run_case(PINNED_MOTOR, TINY_FE, out / "out", comm=comm, quiet=True)["results"]["transient"]
    comm.barrier()                                   # rank 0 has written the series
    with h5py.File(out / "out" / "transient.h5", "r") as f:
        data = {k: f[k][()] for k in f}
    return case, results, data


def test_seating_lifts_the_rotor_onto_the_highest_crest_by_the_modal_tiers_rule():
    comm = MPI.COMM_WORLD
    case = load_case(PINNED_MOTOR, TINY_FE)
    tm = build(case, comm, quiet)
    state, _ = tm.initial_state()
    contact = tm.system.interactions[0]
    z_ref = case.transient.bodies[0].position_m[2]
    lift = state.z[2] - z_ref
    assert contact.smallest_nodal_gap_m(state.u, state.z[:3]) == pytest.approx(0.0, abs=1e-13)
    # n_i . u_i at the band nodes, n the design cone's outward normal there
    nodes = contact._node_dofs
    x = contact._coordinates[nodes[:, 0]]
    e_r = np.column_stack([x[:, 0], x[:, 1], np.zeros(len(x))]) / np.hypot(x[:, 0], x[:, 1])[:, None]
    normal = math.cos(ALPHA) * e_r - math.sin(ALPHA) * np.array([0.0, 0.0, 1.0])
    crest = comm.allreduce(float(np.max(-np.einsum("ij,ij->i", normal, state.u[nodes]), initial=-np.inf)), op=MPI.MAX)
    assert crest > 1e-8                                      # the start has a wave
    # the cone's gap is n.u + sin(alpha) dz to first order in u (|u| ~ 50 nm against r = 13 mm)
    assert lift * math.sin(ALPHA) == pytest.approx(crest, rel=1e-4)
    # the seated rotor starts at rest, touching: the consistent start has no contact force
    assert np.all(state.zd[:3] == 0.0)


def test_a_seated_held_rotor_stays_on_the_crests(seated):
    case, results, data = seated
    z_ref = case.transient.bodies[0].position_m[2]
    z = data["rotor_position_m"][:, 2] - z_ref
    z_seat = z[0] + 0.5 * data["rotor_velocity_m_per_s"][0, 2] * data["dt_s"][0]   # back to t = 0 (at rest)
    assert results["cutbacks"] == 0
    assert z.max() <= z_seat * (1 + 1e-3)                    # never lifted above its seat: not thrown
    assert data["stator_rotor_closed"][len(z) // 3:].mean() > 0.9       # and resting on the crests
    # it starts just touching: no impulse (on the design position the first step takes 3.6 N, 3.7 P)
    preload = -case.transient.bodies[0].applied_force_N[2]
    assert abs(data["stator_rotor_force_N"][0, 2]) < 0.1 * preload



@pytest.mark.mpi
def test_the_fe_tier_writes_the_contact_diagnostics_of_the_modal_tier(seated):
    """The per-site diagnostics under the same names as the modal tier (app/contact/tables.py, one rule in
    app/contact/law.py): every quantity's table, the wave-frame bins (one group: one ring), and their normal force
    equal to the sites' pressure x area over the rows with the wave phase known (the same products summed,
    round-off 1e-12); the motor's summary carries the contact centre and the slip split. On 2 ranks the sites are
    evaluated on the partitions that own them (app/fe/probe.py PointSet) and summed to every rank."""
    from app.contact.tables import BIN_COLUMNS, QUANTITIES, WAVE_BINS

    _, results, data = seated
    names = {f"stator_rotor_sites_{key}" for _, key, _, _ in QUANTITIES} | {"stator_rotor_sites_wave_frame"}
    assert names <= set(data)
    bins = data["stator_rotor_sites_wave_frame"]
    assert bins.shape[1:] == (1, WAVE_BINS, len(BIN_COLUMNS))
    populated = bins[..., 0].reshape(len(bins), -1).sum(axis=1) > 0
    assert not populated[0] and populated[1:].all()
    area = data["stator_rotor_sites_geometry"][:, 3]
    force = bins[populated][..., 1].reshape(int(populated.sum()), -1).sum(axis=1)
    assert np.allclose(force, data["stator_rotor_sites_pressure"][populated] @ area, rtol=1e-12, atol=0)
    assert force.min() > 0
    motor = results["statistics"]["motor"]
    # the rotor rests on the crests, where the stator comes closest to it: the contact's centre is near a crest,
    # not in a trough (180 deg away); 45 deg, a quarter of the way to a trough, is a loose physical bound
    assert abs(motor["contact_centre_from_crest_deg"]) < 45.0
    assert {"slip_speed_circumferential_m_per_s", "slip_speed_meridional_m_per_s",
            "meridional_slip_power_share"} <= set(motor)
