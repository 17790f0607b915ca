"""Small self-contained validation scenes with closed-form answers (used by tests, bench and the
``cases/validation`` files): an elastic rod hitting a rigid wall, a rigid ball dropped on a
Kelvin-Voigt foundation, and a rigid ball on a vibrating elastic block."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem, mesh

from app.transient.contact import MidpointFields, ObstacleShape, PointContact, SurfaceContact
from app.transient.control import StepController, StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.fe import LinearFE
from app.transient.rigid import RigidBody, RigidSet, fixed_body, harmonic_motion
from app.transient.state import TransientState
from app.transient.stepper import TimeStepper
from forms.dynamics import mass
from forms.newmark import TimeScheme
from forms.piezo import elastic_stiffness
from forms.voigt import isotropic_stiffness

STEEL_DENSITY_kg_per_m3 = 7850.0
STEEL_YOUNG_Pa = 200e9


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


@dataclass(frozen=True)
class BallDrop:
    """Rigid steel ball dropped from ``height_m`` (gap) onto a rigid plane through a linear
    Kelvin-Voigt contact (stiffness k, damping c; no pull)."""

    diameter_m: float = 8e-3
    height_m: float = 1e-3
    stiffness_N_per_m: float = 1e7
    damping_N_s_per_m: float = 2.0
    gravity_m_per_s2: float = 9.81

    @property
    def mass_kg(self) -> float:
        return STEEL_DENSITY_kg_per_m3 * math.pi / 6 * self.diameter_m**3

    @property
    def impact_speed_m_per_s(self) -> float:
        return math.sqrt(2 * self.gravity_m_per_s2 * self.height_m)


def ball_drop_closed_form(ball: BallDrop) -> tuple[float, float]:
    """(contact duration [s], coefficient of restitution) of the linear Kelvin-Voigt contact with
    force clipped at zero, gravity included: during contact m x'' + c x' + k x = m g (x penetration)
    with x(0) = 0, x'(0) = v_in; contact ends at the first t > 0 with k x + c x' = 0."""
    m, k, c, g = ball.mass_kg, ball.stiffness_N_per_m, ball.damping_N_s_per_m, ball.gravity_m_per_s2
    v_in = ball.impact_speed_m_per_s
    w0 = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = w0 * math.sqrt(1 - zeta**2)
    x_static = m * g / k
    # x(t) = x_s + e^{-zeta w0 t} (A cos wd t + B sin wd t), A = -x_s, B = (v_in + zeta w0 A) / wd
    A = -x_static
    Bc = (v_in + zeta * w0 * A) / wd

    def x(t):
        return x_static + math.exp(-zeta * w0 * t) * (A * math.cos(wd * t) + Bc * math.sin(wd * t))

    def xd(t):
        e = math.exp(-zeta * w0 * t)
        return e * ((-zeta * w0 * A + wd * Bc) * math.cos(wd * t) + (-zeta * w0 * Bc - wd * A) * math.sin(wd * t))

    def force(t):
        return k * x(t) + c * xd(t)

    from scipy.optimize import brentq

    # The force returns to zero near the half period (before it with damping, just after it
    # without damping because gravity holds the ball down); it has no other zero in between.
    t_hi = 1.5 * math.pi / wd
    t_lo = 0.25 * t_hi
    duration = brentq(force, t_lo, t_hi, xtol=1e-15, rtol=1e-13)
    return duration, -xd(duration) / v_in


def build_ball_drop(comm, ball: BallDrop, scheme: TimeScheme):
    """Rigid ball on a rigid plane, 1D vertical (gdim 1: no FE part) -> (system, state)."""
    ball_body = RigidBody("ball", ball.mass_kg, [ball.height_m + ball.diameter_m / 2], [0.0],
                          [-ball.gravity_m_per_s2])
    ground = fixed_body("ground", [0.0])
    rigid = RigidSet([ground, ball_body])
    link = PointContact("ball_ground", "ground", "ball", [1.0], ball.diameter_m / 2,
                        ball.stiffness_N_per_m, ball.damping_N_s_per_m)
    system = CoupledSystem(comm, scheme, None, rigid, [link])
    z, zd, zdd = rigid.initial_state()
    empty = np.zeros(0)
    return system, TransientState(0.0, empty, empty, empty, z, zd, zdd)


def ball_step_sizes(ball: BallDrop, steps_per_contact: int = 200) -> StepSizes:
    contact = math.pi * math.sqrt(ball.mass_kg / ball.stiffness_N_per_m)
    dt = contact / steps_per_contact
    # Free flight is exact for the scheme (constant gravity), so open steps are long; closure is
    # approached by the controller's time-to-contact rule.
    return StepSizes(open_s=2**12 * dt, closed_s=dt, change_s=dt / 8, min_s=dt / 2**16)


def run_scene(system, state, sizes: StepSizes, t_end_s: float, exports=(), track_energy=False):
    """Run to ``t_end_s`` and return (records, final state, statistics)."""
    records = []
    stepper = TimeStepper(system, StepController(sizes), exports=exports, track_energy=track_energy)
    final = stepper.run(state, t_end_s, on_step=records.append)
    return records, final, stepper


def vibrating_block_with_ball(comm, scheme: TimeScheme, amplitude_m: float = 5e-6, frequency_Hz: float = 2000.0,
                              ball_diameter_m: float = 8e-3, contact_stiffness_Pa_per_m: float = 1e13,
                              elements: int = 4, ball_velocity_m_per_s=(0.0, 0.0), ball_gap_m: float = -1e-7,
                              system_class=CoupledSystem):
    """An elastic steel block (plane strain, 10 x 5 mm) shaken at its base, with a rigid ball
    (cylinder per metre of thickness, mass of an 8 mm steel ball per mm) resting on its top face:
    the ball chatters when the table acceleration exceeds g. -> (system, state)."""
    width, height = 10e-3, 5e-3
    msh = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([width, height])], [2 * elements, elements],
                                cell_type=mesh.CellType.quadrilateral, ghost_mode=mesh.GhostMode.shared_facet)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.dx(domain=msh)
    c = fem.Constant(msh, isotropic_stiffness(STEEL_YOUNG_Pa, 0.3))
    rho = fem.Constant(msh, STEEL_DENSITY_kg_per_m3)
    fdim = msh.topology.dim - 1
    base = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[1], 0.0))
    top = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[1], height))
    shake = fem.Function(V)
    omega = 2 * math.pi * frequency_Hz

    def update_dirichlet(t: float) -> None:
        shake.interpolate(lambda x: np.vstack([np.zeros(x.shape[1]),
                                               np.full(x.shape[1], amplitude_m * math.sin(omega * t))]))

    bc = fem.dirichletbc(shake, fem.locate_dofs_topological(V, fdim, base))
    fe = LinearFE(V, V, mass(u, w, rho, dx), elastic_stiffness(u, w, c, "plane_strain", dx), bcs=[bc],
                  update_dirichlet=update_dirichlet)
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


__all__ = ["FrictionBlock", "build_friction_block",
           "RodImpact", "build_rod_impact", "rod_step_sizes", "BallDrop", "ball_drop_closed_form",
           "build_ball_drop", "ball_step_sizes", "run_scene", "vibrating_block_with_ball", "harmonic_motion"]
