"""Coulomb friction: an elastic block pressed on a rigid plane and pulled sideways.

A steel block (plane strain) is pressed on the plane y = 0 by a body load N and pulled by a
tangential body load T ramped up after the normal contact settled. The penalty surface contact with
friction (ANSYS-like MU, FACT, DC, TAUMAX; forms/contact.py) makes it stick while T < mu_s N
(mu_s = FACT mu_d) and slide with friction force mu_d N above. The demo pulls with T = 0.8 mu_s N,
which lies between mu_d N and mu_s N: with FACT = 1.3 static friction holds the block (friction = T),
with FACT = 1 it slides (friction = mu_d N).

    python demos/demo_friction_block.py          # or: mpirun -n 2 python demos/demo_friction_block.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # runnable as ``python demos/<this file>``

import dataclasses  # noqa: E402
import math  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem, mesh  # noqa: E402
from mpi4py import MPI  # noqa: E402

from app.transient.contact import MidpointFields, ObstacleShape, SurfaceContact  # noqa: E402
from app.transient.control import StepSizes  # noqa: E402
from app.transient.coupled import CoupledSystem  # noqa: E402
from app.transient.fe import LinearFE  # noqa: E402
from app.transient.rigid import RigidSet, fixed_body  # noqa: E402
from app.transient.state import TransientState  # noqa: E402
from app.transient.stepper import run_scene  # noqa: E402
from forms.dynamics import mass  # noqa: E402
from forms.newmark import TimeScheme  # noqa: E402
from forms.piezo import elastic_stiffness  # noqa: E402
from forms.voigt import isotropic_stiffness  # noqa: E402

STEEL_DENSITY_kg_per_m3 = 7850.0
STEEL_YOUNG_Pa = 200e9
END_S = 1.2e-3
# Stuck, the friction balances T up to the regularised law's creep (eps = 1e-4 m/s): 1e-6; sliding,
# it is mu_d N up to the slip-speed decay (DC) still acting: 1e-3.
STICK_RTOL = 1e-6
SLIDE_RTOL = 1e-3


@dataclass(frozen=True)
class FrictionBlock:
    """An elastic steel block (plane strain, per metre of thickness) pressed on a rigid plane by a
    uniform body load (total normal force N) and pulled by a tangential body load T(t) ramped up
    after the normal contact has settled. Coulomb: it sticks while T < mu_s N and slides with
    friction force mu_d N (or the TAUMAX cap x contact width) above."""

    width_m: float = 10e-3
    height_m: float = 5e-3
    normal_acceleration_m_per_s2: float = 1000.0    # N = m * this
    tangential_force_N: float = 0.0                 # T (per metre of thickness)
    ramp_start_s: float = 1e-4
    ramp_s: float = 2e-4
    penalty_Pa_per_m: float = 4e12
    normal_damping_Pa_s_per_m: float = 2.5e7        # ~ critical for the block bouncing on the penalty
    mu_dynamic: float = 0.3
    static_ratio: float = 1.3                       # FACT
    decay_s_per_m: float = 100.0                    # DC
    shear_cap_Pa: float = 1e20                      # TAUMAX
    regularisation_speed_m_per_s: float = 1e-4
    obstacle_radius_m: float | None = None          # None: the plane y = 0; else a sphere touching it at the
                                                    # block's middle from below (centre (w/2, -R))

    @property
    def mass_kg(self) -> float:
        return STEEL_DENSITY_kg_per_m3 * self.width_m * self.height_m

    @property
    def normal_force_N(self) -> float:
        return self.mass_kg * self.normal_acceleration_m_per_s2

    def tangential_scale(self, t: float) -> float:
        return min(max((t - self.ramp_start_s) / self.ramp_s, 0.0), 1.0)


def build_friction_block(comm, block: FrictionBlock, scheme: TimeScheme, elements: int = 2):
    """-> (CoupledSystem, initial state) of :class:`FrictionBlock`: the block rests on the plane y = 0
    or on top of a sphere (the fixed body "ground"), contact "block_ground" on its bottom facets with
    friction."""
    from app.transient.contact import Friction

    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([block.width_m, block.height_m])],
                                [2 * elements, elements], cell_type=mesh.CellType.quadrilateral,
                                ghost_mode=mesh.GhostMode.shared_facet)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.dx(domain=msh)
    c = fem.Constant(msh, isotropic_stiffness(STEEL_YOUNG_Pa, 0.3))
    rho = fem.Constant(msh, STEEL_DENSITY_kg_per_m3)
    m_form = mass(u, w, rho, dx)
    loads = []
    for k, scale in ((1, lambda t: -block.normal_acceleration_m_per_s2),
                     (0, lambda t: block.tangential_force_N / block.mass_kg * block.tangential_scale(t))):
        t_k = fem.Function(V)
        t_k.interpolate(lambda x, k=k: np.vstack([np.full(x.shape[1], float(i == k)) for i in range(2)]))
        loads.append((ufl.action(m_form, t_k), scale))
    fe = LinearFE(V, V, m_form, elastic_stiffness(u, w, c, "plane_strain", dx), loads=loads)
    fdim = msh.topology.dim - 1
    bottom = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[1], 0.0))
    tags = mesh.meshtags(msh, fdim, np.sort(bottom), np.full(bottom.size, 1, dtype=np.int32))
    if block.obstacle_radius_m is None:
        rigid = RigidSet([fixed_body("ground", [0.0, 0.0])])
        shape = ObstacleShape("plane", normal=(0.0, 1.0))
    else:
        rigid = RigidSet([fixed_body("ground", [0.5 * block.width_m, -block.obstacle_radius_m])])
        shape = ObstacleShape("sphere", radius_m=block.obstacle_radius_m, normal=(0.0, 1.0))
    friction = Friction(block.mu_dynamic, block.static_ratio, block.decay_s_per_m, block.shear_cap_Pa,
                        block.regularisation_speed_m_per_s)
    contact = SurfaceContact("block_ground", fe, tags, 1, "ground", shape,
                             block.penalty_Pa_per_m, block.normal_damping_Pa_s_per_m, friction=friction,
                             fields=MidpointFields(fe))
    system = CoupledSystem(comm, scheme, fe, rigid, [contact])
    z, zd, zdd = rigid.initial_state()
    n = fem.Function(V).x.array.size
    return system, TransientState(0.0, np.zeros(n), np.zeros(n), np.zeros(n), z, zd, zdd)


def mean_friction_N(comm, block: FrictionBlock) -> float:
    """Mean friction force on the plane over the last third of the run [N]."""
    system, state = build_friction_block(comm, block, TimeScheme.generalized_alpha(0.5))
    sizes = StepSizes(open_s=1e-6, closed_s=1e-6, change_s=2.5e-7, min_s=1e-12)
    records, _, _ = run_scene(system, state, sizes, END_S)
    system.destroy()
    t = np.array([r["time_s"] for r in records])
    force = np.array([r["contact_force_N"]["block_ground"] for r in records])
    return float(force[t > 2 * END_S / 3, 0].mean())


def main(comm=MPI.COMM_WORLD) -> dict:
    base = FrictionBlock()
    N = base.normal_force_N
    T = 0.8 * base.static_ratio * base.mu_dynamic * N
    stuck = mean_friction_N(comm, dataclasses.replace(base, tangential_force_N=T))
    sliding = mean_friction_N(comm, dataclasses.replace(base, tangential_force_N=T, static_ratio=1.0))
    if comm.rank == 0:
        print(f"N = {N:.2f} N, T = {T:.3f} N: FACT = {base.static_ratio}: friction {stuck:.4f} N (sticks: T); "
              f"FACT = 1: friction {sliding:.4f} N (slides: mu_d N = {base.mu_dynamic * N:.4f} N)")
    return {"pull_N": T, "stuck_friction_N": stuck, "sliding_friction_N": sliding,
            "dynamic_friction_N": base.mu_dynamic * N}


def check(result: dict) -> None:
    assert math.isclose(result["stuck_friction_N"], result["pull_N"], rel_tol=STICK_RTOL), result
    assert math.isclose(result["sliding_friction_N"], result["dynamic_friction_N"], rel_tol=SLIDE_RTOL), result


if __name__ == "__main__":
    check(main())
