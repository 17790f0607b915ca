"""Prescribed motions of FE facets in the transient analysis (``[[transient.base_motions]]``).

A base motion holds the displacement DOFs of a facet group at values given as a function of
position and time, the way a shaker table or a stator surface drives what sits on it. The values
enter through the transient's time-varying Dirichlet data (set before every step, see
:class:`app.transient.fe.LinearFE`): the mass, damping and stiffness rows of the free DOFs see the
prescribed acceleration, velocity and displacement, and a resumed run needs nothing saved because
the motion is a function of t alone.

Registry: :data:`BASE_MOTIONS` maps the case's ``kind`` to a builder (section, prefix, context) ->
motion object with ``dofs`` (local indices into the u-phi space) and ``set_values(t, values)``
(writes the prescribed displacement of those DOFs into the Dirichlet Function's array).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from dolfinx import fem

from app.errors import CaseError


def smooth_ramp(t_s: float, ramp_s: float) -> float:
    """0 -> 1 over [0, ramp_s] as (1 - cos(pi t / ramp_s)) / 2: zero slope at both ends, so a motion
    started from rest has no velocity jump (0 for ramp_s = 0 is not used: 1 at once)."""
    if ramp_s <= 0.0 or t_s >= ramp_s:
        return 1.0
    if t_s <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t_s / ramp_s))


@dataclass
class TravellingWaveMotion:
    """u(x, t) = r(t) [W cos xi n + U_t sin xi e],  xi = k (x . e) - omega t,  k = 2 pi / wavelength.

    The wave travels along the unit vector e at omega / k; W is the normal amplitude along the unit
    vector n, U_t the tangential one along e. With U_t > 0 a crest (xi = 0) moves along -e at
    omega U_t: the surface of a bending plate carrying a flexural wave has U_t = k (h/2) W on its
    top face, and a slider on it is driven against the wave (app.references.friction_drive). r(t) is the
    smooth ramp over ``ramp_periods`` drive periods."""

    name: str
    dofs: np.ndarray              # local u-phi indices of the displacement DOFs held
    axis: np.ndarray              # mesh axis of each of them
    coordinates_m: np.ndarray     # (n, gdim) reference positions of those DOFs
    normal_amplitude_m: float
    tangential_amplitude_m: float
    wavenumber_per_m: float
    omega_rad_per_s: float
    direction: np.ndarray         # e (gdim)
    normal: np.ndarray            # n (gdim)
    ramp_s: float

    def __post_init__(self):
        self._along_m = self.coordinates_m @ self.direction
        self._n_comp = self.normal[self.axis]
        self._e_comp = self.direction[self.axis]

    def set_values(self, t_s: float, values: np.ndarray) -> None:
        xi = self.wavenumber_per_m * self._along_m - self.omega_rad_per_s * t_s
        scale = smooth_ramp(t_s, self.ramp_s)
        values[self.dofs] = scale * (self.normal_amplitude_m * np.cos(xi) * self._n_comp
                                     + self.tangential_amplitude_m * np.sin(xi) * self._e_comp)


def _unit(key: str, value, gdim: int, file: str, prefix: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.size != gdim:
        raise CaseError(file, f"{prefix}.{key}", f"needs {gdim} components (mesh axes)")
    norm = float(np.linalg.norm(v))
    if not norm > 0:
        raise CaseError(file, f"{prefix}.{key}", "must not be the zero vector")
    return v / norm


def displacement_dofs_on_facets(model, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local u-phi indices of the displacement DOFs on ``facets`` (owned and ghost), the mesh axis
    of each, and their reference coordinates (gdim)."""
    W = model.W
    gdim = model.mesh.geometry.dim
    fdim = model.mesh.topology.dim - 1
    dofs, axes, coords = [], [], []
    for k in range(gdim):
        sub = W.sub(0).sub(k)
        collapsed, _ = sub.collapse()
        d_parent, d_collapsed = fem.locate_dofs_topological((sub, collapsed), fdim, facets)
        dofs.append(np.asarray(d_parent))
        axes.append(np.full(len(d_parent), k))
        coords.append(collapsed.tabulate_dof_coordinates()[np.asarray(d_collapsed), :gdim])
    return (np.concatenate(dofs).astype(np.int32), np.concatenate(axes),
            np.concatenate(coords) if coords else np.zeros((0, gdim)))


def build_travelling_wave(section, prefix: str, ctx) -> TravellingWaveMotion:
    from app.fe.model import facet_group_tag

    model, file = ctx.model, ctx.file
    gdim = model.mesh.geometry.dim
    tag = facet_group_tag(model.mesh_data.facet_names, section.facets, file, f"{prefix}.facets")
    md = model.mesh_data
    facets = md.facet_tags.indices[md.facet_tags.values == tag]
    direction = _unit("direction", section.direction, gdim, file, prefix)
    normal = _unit("normal", section.normal, gdim, file, prefix)
    if abs(float(direction @ normal)) > 1e-9:
        raise CaseError(file, f"{prefix}.normal", "must be perpendicular to direction")
    frequency = section.frequency_Hz or ctx.case.transient.drive.frequency_Hz
    dofs, axes, coords = displacement_dofs_on_facets(model, facets)
    if model.comm.allreduce(dofs.size) == 0:
        raise CaseError(file, f"{prefix}.facets", "selects no displacement DOFs")
    return TravellingWaveMotion(section.name, dofs, axes, coords, section.normal_amplitude_m,
                                section.tangential_amplitude_m, 2 * math.pi / section.wavelength_m,
                                2 * math.pi * frequency, direction, normal, section.ramp_periods / frequency)


BASE_MOTIONS = {"travelling_wave": build_travelling_wave}


@dataclass
class MotionContext:
    case: object
    model: object
    file: str


def build_motions(case, model) -> list:
    """The base motions of ``case`` (validated against the mesh); CaseError names the key."""
    ctx = MotionContext(case, model, case.source)
    motions = []
    for i, section in enumerate(case.transient.base_motions):
        motion = BASE_MOTIONS[section.kind](section, f"transient.base_motions[{i}]", ctx)
        for j, other in enumerate(motions):     # facet groups meeting at an edge: each prescribes the shared DOFs
            if model.comm.allreduce(np.intersect1d(motion.dofs, other.dofs).size) > 0:
                raise CaseError(ctx.file, f"transient.base_motions[{i}].facets",
                                f"shares displacement DOFs with base_motions[{j}] ({other.name!r}): a DOF follows "
                                "one prescribed motion")
        motions.append(motion)
    return motions


class DirichletData:
    """The transient's time-varying Dirichlet values: the electrode drive, then every base motion,
    written into the one Function the Dirichlet condition was built from."""

    def __init__(self, values: fem.Function, drive, motions: list):
        self.values, self.drive, self.motions = values, drive, motions

    def __call__(self, t_s: float) -> None:
        self.drive(t_s)
        for motion in self.motions:
            motion.set_values(t_s, self.values.x.array)
