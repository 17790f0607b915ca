"""The ``[transient]`` table of a case file: time integration, step sizes, drive, initial state, rigid
bodies (``[[transient.bodies]]``) and contacts (``[[transient.contacts]]``). SI units in every name.

Checks that need the mesh (a contact naming a facet group that is not in the mesh) happen in
:mod:`app.transient.driver` and raise the same :class:`CaseError` naming
``transient.contacts[i].facets``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from app.case.validate import param
from app.errors import CaseError

TagRef = str | int


@dataclass(frozen=True)
class SchemeSection:
    kind: Literal["newmark", "generalized_alpha"] = param(
        "generalized_alpha", doc="plain Newmark (beta, gamma) or Chung-Hulbert generalized-alpha (rho_inf)")
    beta: float = param(0.25, gt=0, doc="Newmark beta (kind = 'newmark')")
    gamma: float = param(0.5, ge=0, doc="Newmark gamma (kind = 'newmark')")
    rho_inf: float = param(0.5, ge=0, le=1, doc="spectral radius at omega dt -> inf (kind = 'generalized_alpha')")

    def scheme(self):
        from forms.newmark import TimeScheme

        if self.kind == "newmark":
            return TimeScheme.newmark(self.beta, self.gamma)
        return TimeScheme.generalized_alpha(self.rho_inf)


@dataclass(frozen=True)
class StepSection:
    open_s: float = param(1e-6, gt=0, unit="s", doc="dt while no contact is closed")
    closed_s: float = param(2.5e-7, gt=0, unit="s", doc="dt while some contact is closed")
    change_s: float = param(5e-8, gt=0, unit="s", doc="dt when a contact opens or closes")
    min_s: float = param(1e-12, gt=0, unit="s", doc="cut-back floor: below it the run stops (exit 1)")

    def check(self, file, prefix):
        if self.min_s > self.change_s:
            raise CaseError(file, f"{prefix}.min_s", "must not exceed change_s")


@dataclass(frozen=True)
class DriveSection:
    voltage_V: float = param(0.0, ge=0, unit="V", doc="amplitude on electrodes of kind 'voltage' (if no tip amplitude)")
    frequency_Hz: float = param(20100.0, gt=0, unit="Hz", doc="drive frequency")
    tip_amplitude_m: float | None = param(
        None, gt=0, unit="m", doc="free steady amplitude at `point`; sets the voltage by a harmonic solve")
    point: str = param("tip", doc="named [points] entry the amplitude refers to")


@dataclass(frozen=True)
class BodySection:
    name: str = param(doc="rigid body name, used by contacts")
    position_m: list[float] = param(doc="reference point (mesh axes: r, z axisymmetric)")
    mass_kg: float = param(0.0, ge=0, unit="kg", doc="mass (0 only for a fixed body)")
    velocity_m_per_s: list[float] | None = param(None, doc="initial velocity (default 0)")
    fixed: bool = param(False, doc="immovable obstacle (wall, ground)")
    free_axes: list[bool] | None = param(None, doc="per axis: free (true) or held (false); default all free")
    applied_force_N: list[float] | None = param(None, unit="N", doc="constant applied force (besides gravity)")

    def check(self, file, prefix):
        n = len(self.position_m)
        for key in ("velocity_m_per_s", "free_axes", "applied_force_N"):
            value = getattr(self, key)
            if value is not None and len(value) != n:
                raise CaseError(file, f"{prefix}.{key}", f"needs {n} entries like position_m")
        if not self.fixed and not self.mass_kg > 0:
            raise CaseError(file, f"{prefix}.mass_kg", "a body that is not fixed needs a positive mass")


@dataclass(frozen=True)
class ContactSection:
    name: str = param(doc="contact name (time series key)")
    kind: Literal["surface", "point", "node"] = param(
        doc="FE facets vs rigid body, rigid vs rigid (Kelvin-Voigt), or one FE node vs a rigid sphere (Hertz)")
    stiffness: float = param(gt=0, doc="penalty: Pa/m (surface, FKN as absolute value), N/m (point) or "
                                       "N/m^1.5 (node: Hertz (4/3) E* sqrt(R))")
    damping: float = param(0.0, ge=0, doc="normal damping: Pa s/m (surface) or N s/m (point, node)")
    # surface contacts
    facets: TagRef | None = param(None, doc="facet group of the FE surface (surface)")
    body: str | None = param(None, doc="rigid body the surface or node touches (surface, node)")
    node_point: str | None = param(None, doc="named [points] entry; its nearest FE node is the contact node (node)")
    shape: Literal["plane", "sphere"] = param("plane", doc="obstacle shape of the body (surface)")
    normal: list[float] | None = param(
        None, doc="plane: outward unit normal, towards the FE body; sphere (optional): unit vector from the centre "
                  "towards the contact zone, the gap is then formed without round-off (large radii); node: unit "
                  "vector from sphere centre to node")
    radius_m: float | None = param(None, gt=0, unit="m", doc="sphere radius (surface sphere, node)")
    # point contacts
    lower: str | None = param(None, doc="lower body (point)")
    upper: str | None = param(None, doc="upper body (point)")
    direction: list[float] | None = param(None, doc="unit vector from lower to upper (point)")
    touch_distance_m: float = param(0.0, ge=0, unit="m", doc="centre distance at first touch (point)")

    def check(self, file, prefix):
        if self.kind == "surface":
            for key in ("facets", "body"):
                if getattr(self, key) is None:
                    raise CaseError(file, f"{prefix}.{key}", "required for a surface contact")
            if self.shape == "plane" and self.normal is None:
                raise CaseError(file, f"{prefix}.normal", "a plane obstacle needs a normal")
            if self.shape == "sphere" and self.radius_m is None:
                raise CaseError(file, f"{prefix}.radius_m", "a sphere obstacle needs a radius")
        elif self.kind == "node":
            for key in ("body", "node_point", "radius_m", "normal"):
                if getattr(self, key) is None:
                    raise CaseError(file, f"{prefix}.{key}", "required for a node contact")
        else:
            for key in ("lower", "upper", "direction"):
                if getattr(self, key) is None:
                    raise CaseError(file, f"{prefix}.{key}", "required for a point contact")

    def bodies(self) -> list[tuple[str, str]]:
        """(key, body name) pairs this contact refers to."""
        keys = ("body",) if self.kind in ("surface", "node") else ("lower", "upper")
        return [(k, getattr(self, k)) for k in keys]


@dataclass(frozen=True)
class LoadSection:
    gravity_m_per_s2: list[float] | None = param(None, doc="gravity vector on FE and rigid bodies (mesh axes)")
    fe_force_N: list[float] | None = param(
        None, unit="N", doc="constant total force on the FE body (downforce), distributed like its mass")


@dataclass(frozen=True)
class TransientSection:
    end_time_s: float = param(gt=0, unit="s", doc="simulated time")
    output_interval_s: float = param(gt=0, unit="s", doc="time between field outputs and progress updates")
    checkpoint_interval_steps: int = param(
        1000, ge=0, doc="checkpoint (for `piezodyn run --resume DIR`) every N steps and at the end; 0: end only")
    scheme: SchemeSection = param(default_factory=SchemeSection, doc="see [transient.scheme]")
    steps: StepSection = param(default_factory=StepSection, doc="see [transient.steps]")
    drive: DriveSection = param(default_factory=DriveSection, doc="see [transient.drive]")
    initial_state: Literal["rest", "harmonic"] = param(
        "rest", doc="start at rest, or from the scaled harmonic steady state (drive then V cos wt)")
    loads: LoadSection = param(default_factory=LoadSection, doc="see [transient.loads]")
    bodies: list[BodySection] = param(default_factory=list, doc="rigid bodies")
    contacts: list[ContactSection] = param(default_factory=list, doc="penalty contacts")
    min_flight_rise_m: float = param(
        50e-6, gt=0, unit="m", doc="statistics: a flight of the FE body rises at least this much (as the lumped tier)")

    def check(self, file, prefix):
        steps = self.steps
        largest = max(steps.open_s, steps.closed_s, steps.change_s)
        if largest > self.output_interval_s:
            key = next(k for k in ("open_s", "closed_s", "change_s") if getattr(steps, k) == largest)
            raise CaseError(file, f"{prefix}.steps.{key}",
                            f"dt = {largest} s is larger than output_interval_s = {self.output_interval_s} s")
        if self.output_interval_s > self.end_time_s:
            raise CaseError(file, f"{prefix}.output_interval_s", "must not exceed end_time_s")
        names = [b.name for b in self.bodies]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise CaseError(file, f"{prefix}.bodies[{i}].name", f"duplicate rigid body name {name!r}")
        dims = {len(b.position_m) for b in self.bodies}
        if len(dims) > 1:
            raise CaseError(file, f"{prefix}.bodies", "all bodies need the same number of coordinates")
        for i, contact in enumerate(self.contacts):
            for key, name in contact.bodies():
                if name not in names:
                    known = ", ".join(names) or "none"
                    raise CaseError(file, f"{prefix}.contacts[{i}].{key}",
                                    f"unknown rigid body {name!r} (bodies: {known})")
        contact_names = [c.name for c in self.contacts]
        for i, name in enumerate(contact_names):
            if name in contact_names[:i]:
                raise CaseError(file, f"{prefix}.contacts[{i}].name", f"duplicate contact name {name!r}")
