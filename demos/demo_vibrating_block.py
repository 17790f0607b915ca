"""A rigid ball chattering on a shaken elastic block.

An elastic steel block (plane strain, 10 x 5 mm) is shaken at its base at 3 kHz with 0.3 µm
amplitude: the table acceleration A w^2 is about 11 g, so a ball resting on its top face (a rigid
cylinder with the mass of an 8 mm steel ball per mm of thickness, penalty surface contact with a
sphere obstacle) is thrown off and lands again, again. The demo shows that the adaptive time
stepping (open / closed / changing step sizes, event refinement, cut-back) carries such repeated
impacts through: it reports the impacts and the largest flight height, and checks the ball flew.

    python demos/demo_vibrating_block.py         # or: mpirun -n 2 python demos/demo_vibrating_block.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # runnable as ``python demos/<this file>``

import math  # noqa: E402

import numpy as np  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem, mesh  # noqa: E402
from mpi4py import MPI  # noqa: E402

from app.transient.contact import MidpointFields, ObstacleShape, SurfaceContact  # noqa: E402
from app.transient.control import StepSizes  # noqa: E402
from app.transient.coupled import CoupledSystem  # noqa: E402
from app.transient.fe import LinearFE  # noqa: E402
from app.transient.rigid import RigidBody, RigidSet  # noqa: E402
from app.transient.state import TransientState  # noqa: E402
from app.transient.stepper import run_scene  # noqa: E402
from forms.dynamics import mass  # noqa: E402
from forms.newmark import TimeScheme  # noqa: E402
from forms.piezo import elastic_stiffness  # noqa: E402
from forms.voigt import isotropic_stiffness  # noqa: E402

STEEL_DENSITY_kg_per_m3 = 7850.0
STEEL_YOUNG_Pa = 200e9
END_S = 4e-3


def elastic_block(comm, nx: int, ny: int, young_Pa: float = STEEL_YOUNG_Pa, width_m: float = 10e-3,
                  height_m: float = 5e-3):
    """A steel block [0, width] x [0, height] in plane strain, nx x ny linear quadrilaterals ->
    (V, mass form, stiffness form, the base facets y = 0) for a :class:`LinearFE`."""
    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([width_m, height_m])], [nx, ny],
                                cell_type=mesh.CellType.quadrilateral, ghost_mode=mesh.GhostMode.shared_facet)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.dx(domain=msh)
    c = fem.Constant(msh, isotropic_stiffness(young_Pa, 0.3))
    rho = fem.Constant(msh, STEEL_DENSITY_kg_per_m3)
    base = mesh.locate_entities_boundary(msh, msh.topology.dim - 1, lambda x: np.isclose(x[1], 0.0))
    return V, mass(u, w, rho, dx), elastic_stiffness(u, w, c, "plane_strain", dx), base


def vibrating_block_with_ball(comm, scheme: TimeScheme, amplitude_m: float = 5e-6, frequency_Hz: float = 2000.0,
                              ball_diameter_m: float = 8e-3, contact_stiffness_Pa_per_m: float = 1e13,
                              elements: int = 4, ball_velocity_m_per_s=(0.0, 0.0), ball_gap_m: float = -1e-7,
                              system_class=CoupledSystem):
    """An elastic steel block (plane strain, 10 x 5 mm) shaken at its base, with a rigid ball
    (cylinder per metre of thickness, mass of an 8 mm steel ball per mm) resting on its top face:
    the ball chatters when the table acceleration exceeds g. -> (system, state)."""
    width, height = 10e-3, 5e-3
    V, mass_form, stiffness_form, base = elastic_block(comm, 2 * elements, elements, width_m=width, height_m=height)
    msh = V.mesh
    fdim = msh.topology.dim - 1
    top = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[1], height))
    shake = fem.Function(V)
    omega = 2 * math.pi * frequency_Hz

    def update_dirichlet(t: float) -> None:
        shake.interpolate(lambda x: np.vstack([np.zeros(x.shape[1]),
                                               np.full(x.shape[1], amplitude_m * math.sin(omega * t))]))

    bc = fem.dirichletbc(shake, fem.locate_dofs_topological(V, fdim, base))
    fe = LinearFE(V, V, mass_form, stiffness_form, bcs=[bc], update_dirichlet=update_dirichlet)
    tags = mesh.meshtags(msh, fdim, np.sort(top), np.full(top.size, 1, dtype=np.int32))
    radius = ball_diameter_m / 2
    ball_mass = STEEL_DENSITY_kg_per_m3 * math.pi / 6 * ball_diameter_m**3 / 1e-3
    # A ball moving sideways is free in x; otherwise x is held (it would only drift by round-off).
    sideways = ball_velocity_m_per_s[0] != 0.0
    ball = RigidBody("ball", ball_mass, [width / 2, height + radius + ball_gap_m], list(ball_velocity_m_per_s),
                     [0.0, -9.81], prescribed_axes=(not sideways, False))
    rigid = RigidSet([ball])
    fields = MidpointFields(fe)
    contact = SurfaceContact("block_ball", fe, tags, 1, "ball", ObstacleShape("sphere", radius_m=radius),
                             contact_stiffness_Pa_per_m, damping_Pa_s_per_m=0.0, fields=fields)
    system = system_class(comm, scheme, fe, rigid, [contact])
    z, zd, zdd = rigid.initial_state()
    n = fem.Function(V).x.array.size
    return system, TransientState(0.0, np.zeros(n), np.zeros(n), np.zeros(n), z, zd, zdd)


def main(comm=MPI.COMM_WORLD) -> dict:
    system, state = vibrating_block_with_ball(comm, TimeScheme.generalized_alpha(0.7), amplitude_m=0.3e-6,
                                              frequency_Hz=3000.0)
    sizes = StepSizes(open_s=2.5e-6, closed_s=5e-7, change_s=5e-8, min_s=1e-12)
    records, final, stepper = run_scene(system, state, sizes, END_S)
    system.destroy()
    closed = np.array([r["contact_closed"][0] for r in records])
    heights = np.array([r["position_m"][1] for r in records])
    result = {"end_s": final.t, "impacts": int(np.sum(np.diff(closed) == 1)),
              "largest_rise_m": float(heights.max() - heights[0]), "cutbacks": stepper.stats.cutbacks}
    if comm.rank == 0:
        print(f"{result['impacts']} impacts in {END_S * 1e3:g} ms, largest rise "
              f"{result['largest_rise_m'] * 1e6:.2f} um, {len(records)} steps, {result['cutbacks']} cut-backs")
    return result


def check(result: dict) -> None:
    assert math.isclose(result["end_s"], END_S, rel_tol=1e-12), result
    assert result["impacts"] >= 2, result            # thrown off and landed again, at least twice
    assert result["largest_rise_m"] > 1e-6, result    # it really flew (the table moves 0.3 um)


if __name__ == "__main__":
    check(main())
