"""Saint-Venant's rod impact: an elastic rod hits a rigid wall.

An elastic rod (plane strain, Poisson 0, so the bar-wave speed is exactly c = sqrt(E / rho)) of length
L moves at v0 towards a rigid wall a gap away from its end. The compression wave runs to the free end
and back: the contact lasts 2 L / c and carries the force rho c A v0 (A per metre of thickness). The
demo builds the rod with dolfinx, the wall as a fixed rigid body and a penalty surface contact
(app.transient.contact.SurfaceContact), steps it with generalized-alpha (rho_inf = 0.5) and compares
the contact pulse with those closed forms.

    python demos/demo_rod_impact.py              # or: mpirun -n 2 python demos/demo_rod_impact.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # runnable as ``python demos/<this file>``

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
# Tolerances of the comparison (40 elements, one step per element transit): the pulse edges are
# resolved to about one step (3 % of the duration at 40 elements); the force plateau to 1 %.
DURATION_RTOL = 0.03
FORCE_RTOL = 0.01


@dataclass(frozen=True)
class RodImpact:
    """Elastic rod (plane strain, Poisson 0, so the bar-wave speed is exactly sqrt(E/rho)) of length
    L moving at v0 towards a rigid wall a gap away from its end. Saint-Venant: contact lasts 2L/c
    and the force is rho c A v0 (A per metre of thickness here)."""

    length_m: float = 0.1
    height_m: float = 0.01
    elements_along: int = 40
    degree: int = 1
    speed_m_per_s: float = 1.0
    gap_m: float = 1e-7
    young_Pa: float = STEEL_YOUNG_Pa
    density_kg_per_m3: float = STEEL_DENSITY_kg_per_m3
    penalty_factor: float = 10.0

    @property
    def wave_speed_m_per_s(self) -> float:
        return math.sqrt(self.young_Pa / self.density_kg_per_m3)

    @property
    def contact_duration_s(self) -> float:
        return 2 * self.length_m / self.wave_speed_m_per_s

    @property
    def contact_force_N(self) -> float:
        return self.density_kg_per_m3 * self.wave_speed_m_per_s * self.height_m * self.speed_m_per_s

    @property
    def element_length_m(self) -> float:
        return self.length_m / self.elements_along

    @property
    def penalty_Pa_per_m(self) -> float:
        """Penalty per area: ``penalty_factor`` x the axial stiffness per area of one element."""
        return self.penalty_factor * self.young_Pa / self.element_length_m


def build_rod_impact(comm, rod: RodImpact, scheme: TimeScheme, system_class=CoupledSystem):
    """-> (``system_class`` instance, initial state)."""
    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([rod.length_m, rod.height_m])],
                                [rod.elements_along, 1], cell_type=mesh.CellType.quadrilateral,
                                ghost_mode=mesh.GhostMode.shared_facet)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", rod.degree))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.dx(domain=msh)  # plane strain per metre of thickness (volume weight 1)
    c = fem.Constant(msh, isotropic_stiffness(rod.young_Pa, 0.0))
    rho = fem.Constant(msh, rod.density_kg_per_m3)
    # The transverse direction is left free: with Poisson 0 it stays unloaded.
    fe = LinearFE(V, V, mass(u, w, rho, dx), elastic_stiffness(u, w, c, "plane_strain", dx))
    fdim = msh.topology.dim - 1
    end = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], rod.length_m))
    tags = mesh.meshtags(msh, fdim, np.sort(end), np.full(end.size, 1, dtype=np.int32))
    wall = fixed_body("wall", [rod.length_m + rod.gap_m, 0.0])
    rigid = RigidSet([wall])
    fields = MidpointFields(fe)
    contact = SurfaceContact("rod_wall", fe, tags, 1, "wall", ObstacleShape("plane", normal=(-1.0, 0.0)),
                             rod.penalty_Pa_per_m, fields=fields)
    system = system_class(comm, scheme, fe, rigid, [contact])
    u0 = fem.Function(V)
    v0 = fem.Function(V)
    v0.interpolate(lambda x: np.vstack([np.full(x.shape[1], rod.speed_m_per_s), np.zeros(x.shape[1])]))
    z, zd, zdd = rigid.initial_state()
    n = u0.x.array.size
    state = TransientState(0.0, u0.x.array.copy(), v0.x.array.copy(), np.zeros(n), z, zd, zdd)
    return system, state


def rod_step_sizes(rod: RodImpact, steps_per_element: float = 1.0) -> StepSizes:
    """dt ~ element transit time (the accuracy limit of a wave front on the mesh)."""
    transit = rod.element_length_m / rod.wave_speed_m_per_s
    dt = transit / steps_per_element
    return StepSizes(open_s=4 * dt, closed_s=dt, change_s=dt / 4, min_s=dt / 4096)


def contact_pulse(records, name="rod_wall"):
    """(duration [s], impulse-mean force [N], median force over the pulse [N], peak [N]) of the
    contact force on the wall (+x)."""
    t = np.array([0.0] + [r["time_s"] for r in records])
    f = np.array([0.0] + [r["contact_force_N"][name][0] for r in records])
    on = np.flatnonzero(f > 0)
    assert on.size > 5, "no contact happened"
    first, last = on[0], on[-1]
    outer = t[last + 1] - t[first - 1]
    inner = t[last] - t[first]
    duration = 0.5 * (outer + inner)
    impulse = float(np.trapz(f, t))
    return duration, impulse / duration, float(np.median(f[first:last + 1])), float(f.max())


def main(comm=MPI.COMM_WORLD) -> dict:
    rod = RodImpact(elements_along=40)
    system, state = build_rod_impact(comm, rod, TimeScheme.generalized_alpha(0.5))
    records, _, _ = run_scene(system, state, rod_step_sizes(rod), 1.4 * rod.contact_duration_s)
    system.destroy()
    duration, _, median_force, _ = contact_pulse(records)
    result = {"duration_s": duration, "expected_duration_s": rod.contact_duration_s,
              "force_N": median_force, "expected_force_N": rod.contact_force_N}
    if comm.rank == 0:
        print(f"contact duration {duration * 1e6:.3f} us (2L/c = {rod.contact_duration_s * 1e6:.3f} us), "
              f"force {median_force:.1f} N (rho c A v0 = {rod.contact_force_N:.1f} N)")
    return result


def check(result: dict) -> None:
    assert math.isclose(result["duration_s"], result["expected_duration_s"], rel_tol=DURATION_RTOL), result
    assert math.isclose(result["force_N"], result["expected_force_N"], rel_tol=FORCE_RTOL), result


if __name__ == "__main__":
    check(main())
