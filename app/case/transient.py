"""The ``[transient]`` table of a case file: time integration, step sizes, drive, initial state, rigid
bodies (``[[transient.bodies]]``) and contacts (``[[transient.contacts]]``). SI units in every name.

Checks that need the mesh (a contact naming a facet group that is not in the mesh) happen in
:mod:`app.transient.driver` and raise the same :class:`CaseError` naming
``transient.contacts[i].facets``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from app.case.validate import param, refuse_repeats
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
    lock: Literal["none", "resonance"] = param(
        "none", doc="'resonance': drive at the tier's own model's resonance nearest frequency_Hz plus detuning_Hz, "
                    "as a phase-locked driver holds a stated detuning (the drive then does not depend on how far the "
                    "mesh puts the resonance); frequency_Hz is where the resonance is sought and the reduced "
                    "basis's reference frequency. The summary reports it (transient.drive)")
    lock_modes: int = param(
        2, ge=1, le=8, doc="lock = 'resonance': the resonance is the mean of the model's natural frequencies "
                           "(electrodes short-circuited) nearest frequency_Hz, this many: 2 for a travelling wave's "
                           "mode pair, 1 for a single mode")
    detuning_Hz: float = param(
        0.0, unit="Hz", doc="lock = 'resonance': drive frequency minus the model's resonance (positive: above it)")

    def check(self, file, prefix):
        if self.lock == "none":
            for key, default in (("detuning_Hz", 0.0), ("lock_modes", 2)):
                if getattr(self, key) != default:
                    raise CaseError(file, f"{prefix}.{key}", "needs lock = 'resonance'")
        elif abs(self.detuning_Hz) >= 0.5 * self.frequency_Hz:
            raise CaseError(file, f"{prefix}.detuning_Hz", f"{self.detuning_Hz:g} Hz is not a detuning of a "
                                                           f"resonance near {self.frequency_Hz:g} Hz")


@dataclass(frozen=True)
class RotationSection:
    axis: Literal["x", "y", "z", "plane"] = param(
        doc="rotation axis through the body's reference point: x, y or z in 3D; 'plane' in 2D (plane strain: "
            "counter-clockwise from the first mesh axis to the second)")
    motion: Literal["free", "constant_rate", "fixed"] = param(
        "free", doc="free (integrated), prescribed at constant rate_rad_per_s (a spinning rotor), or fixed")
    inertia_kg_m2: float = param(0.0, ge=0, unit="kg m^2", doc="moment of inertia about the axis (free rotation)")
    angle_rad: float = param(0.0, unit="rad", doc="initial angle")
    rate_rad_per_s: float = param(
        0.0, unit="rad/s", doc="initial (free) or prescribed (constant_rate) angular velocity")
    torque_N_m: float = param(0.0, unit="N m", doc="constant applied torque about the axis (free rotation)")
    brake_N_m_s_per_rad: float = param(
        0.0, ge=0, unit="N m s/rad", doc="viscous brake: adds -brake * angular velocity to the applied torque "
                                         "(free rotation)")

    def check(self, file, prefix):
        if self.motion == "free" and not self.inertia_kg_m2 > 0:
            raise CaseError(file, f"{prefix}.inertia_kg_m2", "a free rotation needs a positive inertia")
        if self.motion != "free" and self.brake_N_m_s_per_rad:
            raise CaseError(file, f"{prefix}.brake_N_m_s_per_rad", "a brake acts on a free rotation only")
        if self.motion == "fixed" and self.rate_rad_per_s != 0.0:
            raise CaseError(file, f"{prefix}.rate_rad_per_s", "a fixed rotation has no rate (use constant_rate)")


@dataclass(frozen=True)
class BodySection:
    name: str = param(doc="rigid body name, used by contacts")
    position_m: list[float] = param(doc="reference point (mesh axes: r, z axisymmetric)")
    mass_kg: float = param(0.0, ge=0, unit="kg", doc="mass (0 only for a fixed body)")
    velocity_m_per_s: list[float] | None = param(
        None, doc="initial velocity (default 0); a held axis moves at this constant velocity (a belt)")
    fixed: bool = param(False, doc="immovable obstacle (wall, ground)")
    free_axes: list[bool] | None = param(
        None, doc="per axis: free (true) or held (false, moving at its velocity_m_per_s); default all free")
    applied_force_N: list[float] | None = param(None, unit="N", doc="constant applied force (besides gravity)")
    rotations: list[RotationSection] = param(
        default_factory=list, doc="rotational DOFs [[transient.bodies.rotations]] (none: the body only translates)")
    seat_on: str | None = param(
        None, doc="surface contact (name) the body starts seated on: before the first step it moves along its one "
                  "free translation axis until that contact's smallest nodal gap, over the initial (rest or "
                  "harmonic) displacement, is zero; position_m stays the contact's reference (docs/contact.md)")

    def check(self, file, prefix):
        n = len(self.position_m)
        for key in ("velocity_m_per_s", "free_axes", "applied_force_N"):
            value = getattr(self, key)
            if value is not None and len(value) != n:
                raise CaseError(file, f"{prefix}.{key}", f"needs {n} entries like position_m")
        if not self.fixed and not self.mass_kg > 0:
            raise CaseError(file, f"{prefix}.mass_kg", "a body that is not fixed needs a positive mass")
        allowed = ("plane",) if n == 2 else ("x", "y", "z")
        axes = [r.axis for r in self.rotations]
        for i, axis in enumerate(axes):
            if axis not in allowed:
                raise CaseError(file, f"{prefix}.rotations[{i}].axis",
                                f"{axis!r} is not a rotation axis in {n}D (use {', '.join(allowed)})")
            if axis in axes[:i]:
                raise CaseError(file, f"{prefix}.rotations[{i}].axis", f"duplicate rotation axis {axis!r}")
            if self.fixed and self.rotations[i].motion == "free":
                raise CaseError(file, f"{prefix}.rotations[{i}].motion", "a fixed body has no free rotation")


@dataclass(frozen=True)
class SurfaceFrictionSection:
    """Regularised Coulomb friction of a surface contact (ANSYS TB,FRIC / contact real constants)."""

    mu_dynamic: float = param(ge=0, doc="kinetic coefficient mu_d [MU]")
    static_ratio: float = param(1.0, gt=0, doc="mu_s / mu_d [FACT]")
    decay_s_per_m: float = param(0.0, ge=0, unit="s/m", doc="exponential decay of mu with slip speed [DC]")
    shear_cap_Pa: float = param(1e20, gt=0, unit="Pa", doc="largest friction shear stress [TAUMAX]")
    regularisation_speed_m_per_s: float = param(
        1e-4, gt=0, unit="m/s", doc="slip speed below which the law is viscous (stick regularisation)")



@dataclass(frozen=True)
class LinkFrictionSection:
    """Regularised Coulomb friction of a point (rigid-rigid) or node contact: as the surface law, the cap is a
    force."""

    mu_dynamic: float = param(ge=0, doc="kinetic coefficient mu_d [MU]")
    static_ratio: float = param(1.0, gt=0, doc="mu_s / mu_d [FACT]")
    decay_s_per_m: float = param(0.0, ge=0, unit="s/m", doc="exponential decay of mu with slip speed [DC]")
    force_cap_N: float = param(1e20, gt=0, unit="N", doc="largest friction force (TAUMAX times contact area)")
    regularisation_speed_m_per_s: float = param(
        1e-4, gt=0, unit="m/s", doc="slip speed below which the law is viscous (stick regularisation)")



# [[transient.contacts]] is a tagged union on `kind`: one dataclass per kind (app.case.validate
# dispatches a list entry on its `kind` and names a key of another kind). A new kind is a new class
# here plus its entry in app.transient.interactions.INTERACTIONS.
@dataclass(frozen=True, kw_only=True)
class SurfaceContactSection:
    name: str = param(doc="contact name (time series key)")
    kind: Literal["surface"] = param(doc="FE facets against an obstacle shape of a rigid body (penalty)")
    stiffness: float = param(gt=0, unit="Pa/m", doc="penalty per unit area (FKN as an absolute value)")
    damping: float = param(0.0, ge=0, unit="Pa s/m", doc="normal viscous pressure per unit gap rate")
    facets: TagRef = param(doc="facet group of the FE surface")
    body: str = param(doc="rigid body the surface touches")
    shape: Literal["plane", "sphere", "cone"] = param("plane", doc="obstacle shape of the body")
    normal: list[float] | None = param(
        None, doc="plane: outward unit normal, towards the FE body; sphere (optional): unit vector from the centre "
                  "towards the contact zone, the gap is then formed without round-off (large radii)")
    radius_m: float | None = param(
        None, gt=0, unit="m", doc="sphere radius; cone: radius of the conical face at the body's reference point")
    axis: list[float] | None = param(
        None, doc="cone: unit vector along the cone's axis through the body's reference point, in the direction in "
                  "which its radius grows (a solid cone: the FE surface lies outside it)")
    half_angle_deg: float | None = param(
        None, gt=0, lt=90, unit="deg", doc="cone: angle between the conical face and its axis")
    friction: SurfaceFrictionSection | None = param(None, doc="Coulomb friction (none: frictionless)")
    rounding_m: float = param(
        0.0, ge=0, unit="m", doc="the penalty's kink at first touch rounded over this penetration (C^1: k d^2 / (2 d0) "
                                 "below d0, forms/contact.py); 0: none")
    sampling: Literal["nodes", "ring"] = param(
        "nodes", doc="where the modal tier evaluates the law (the FE tier integrates at quadrature points; both report "
                     "diagnostics there): the facet group's nodes with lumped areas, or sample_points evenly round the "
                     "contact circle of a surface of revolution (a cone obstacle, or a body spinning about its axis)")
    sample_points: int = param(
        512, ge=8, le=16384, doc="sampling 'ring': points round the contact circle, each carrying the facet group's "
                                 "area over their number")
    sample_rings: int = param(
        1, ge=1, le=16, doc="sampling 'ring' on a cone: rings of sample_points points across the facet group's height "
                            "(Gauss-Legendre in height, each point carrying its ring's share of the area), as the FE "
                            "tier's facet quadrature samples the band across it; 1: one ring on the contact circle. "
                            "The modal tier needs the band's tilt to see it: reduction.interface = 'band' or "
                            "reduction.site_displacement = 'field' (docs/motor-rotor.md, 'Sampling across the band')")
    exclude_initial_gap: bool = param(
        False, doc="measure each point's gap from its gap at the start, the undeformed surface against the body at "
                   "its position_m (ANSYS KEYOPT(9) = 1, every shape): g_eff = g(x + u, p) - g(x, p_ref). Both initial "
                   "gaps and penetrations are removed, so every point of the facet group touches at the start: for a "
                   "faceted surface that is in contact by design (docs/contact.md)")

    def check(self, file, prefix):
        if self.sample_rings > 1 and (self.sampling != "ring" or self.shape != "cone"):
            raise CaseError(file, f"{prefix}.sample_rings", 'rings across the band need sampling = "ring" on a cone '
                                                            f'(this contact: sampling {self.sampling!r}, shape '
                                                            f'{self.shape!r})')
        if self.shape == "plane" and self.normal is None:
            raise CaseError(file, f"{prefix}.normal", "a plane obstacle needs a normal")
        if self.shape == "sphere" and self.radius_m is None:
            raise CaseError(file, f"{prefix}.radius_m", "a sphere obstacle needs a radius")
        if self.shape == "cone":
            for key in ("radius_m", "axis", "half_angle_deg"):
                if getattr(self, key) is None:
                    raise CaseError(file, f"{prefix}.{key}", "a cone obstacle needs radius_m, axis and half_angle_deg")
            if len(self.axis) != 3 or abs(sum(a * a for a in self.axis) - 1.0) > 1e-9:
                raise CaseError(file, f"{prefix}.axis", "the cone axis must be a unit vector with 3 components")

    def bodies(self) -> list[tuple[str, str]]:
        return [("body", self.body)]


@dataclass(frozen=True, kw_only=True)
class NodeContactSection:
    name: str = param(doc="contact name (time series key)")
    kind: Literal["node"] = param(doc="one FE node against a rigid sphere (Hertz)")
    stiffness: float = param(gt=0, unit="N/m^1.5", doc="Hertz (4/3) E* sqrt(R)")
    damping: float = param(0.0, ge=0, unit="N s/m", doc="normal damping")
    body: str = param(doc="rigid body the node touches")
    node_point: str = param(doc="named [points] entry; its nearest FE node is the contact node")
    radius_m: float = param(gt=0, unit="m", doc="sphere radius")
    normal: list[float] = param(doc="unit vector from the sphere centre to the node")
    friction: LinkFrictionSection | None = param(None, doc="Coulomb friction of the node (none: frictionless)")

    def bodies(self) -> list[tuple[str, str]]:
        return [("body", self.body)]


@dataclass(frozen=True, kw_only=True)
class PointContactSection:
    name: str = param(doc="contact name (time series key)")
    kind: Literal["point"] = param(doc="rigid body against rigid body (Kelvin-Voigt link)")
    stiffness: float = param(gt=0, unit="N/m", doc="link stiffness")
    damping: float = param(0.0, ge=0, unit="N s/m", doc="link damping")
    lower: str = param(doc="lower body")
    upper: str = param(doc="upper body")
    direction: list[float] = param(doc="unit vector from lower to upper")
    touch_distance_m: float = param(0.0, ge=0, unit="m", doc="reference-point distance at first touch")
    contact_offset_m: float = param(
        0.0, ge=0, unit="m", doc="distance from the upper body's reference point to the contact point, against "
                                 "`direction` (the radius of a disc or ball on the lower body): the lever arm of "
                                 "friction")
    friction: LinkFrictionSection | None = param(None, doc="Coulomb friction (none: frictionless)")

    def check(self, file, prefix):
        if self.lower == self.upper:
            raise CaseError(file, f"{prefix}.upper", f"a body does not touch itself: lower is {self.lower!r} too")

    def bodies(self) -> list[tuple[str, str]]:
        return [("lower", self.lower), ("upper", self.upper)]


ContactSection = SurfaceContactSection | NodeContactSection | PointContactSection


@dataclass(frozen=True, kw_only=True)
class TravellingWaveMotionSection:
    """Prescribed travelling wave on a facet group: u = r(t) [W cos xi n + U_t sin xi e],
    xi = 2 pi (x . e) / wavelength - omega t; r(t) ramps from 0 to 1 over ramp_periods
    (app.transient.motions)."""

    name: str = param(doc="motion name")
    kind: Literal["travelling_wave"] = param(doc="travelling wave along `direction` (a stator surface)")
    facets: TagRef = param(
        doc="facet group whose displacement is prescribed (all components); the facet groups of two motions may not "
            "share nodes")
    normal_amplitude_m: float = param(ge=0, unit="m", doc="W: displacement amplitude along `normal`")
    tangential_amplitude_m: float = param(
        ge=0, unit="m", doc="U_t: amplitude along `direction`, a quarter period after the normal one (a crest "
                            "moves against the wave at omega U_t)")
    wavelength_m: float = param(gt=0, unit="m", doc="wavelength along `direction`")
    frequency_Hz: float | None = param(None, gt=0, unit="Hz", doc="wave frequency (default: transient.drive)")
    direction: list[float] = param(doc="unit vector (mesh axes) along which the wave travels")
    normal: list[float] = param(doc="unit vector (mesh axes) of the normal displacement, perpendicular to direction")
    ramp_periods: float = param(
        2.0, gt=0, doc="the amplitude ramps smoothly from 0 over this many periods (the run starts at rest)")


BaseMotionSection = TravellingWaveMotionSection


@dataclass(frozen=True)
class LoadSection:
    gravity_m_per_s2: list[float] | None = param(None, doc="gravity vector on FE and rigid bodies (mesh axes)")
    fe_force_N: list[float] | None = param(
        None, unit="N", doc="constant total force on the FE body (downforce), distributed like its mass")


@dataclass(frozen=True)
class SteadyStateSection:
    """Stop a run once a rotor turns steadily: the mean angular velocity over one drive period changes by less
    than ``relative_tolerance`` over ``window_cycles`` periods (a prescribed or held spin: the mean friction
    torque)."""

    body: str = param(doc="rigid body whose first rotation is watched (the rotor)")
    rule: Literal["window", "trend", "orbit"] = param(
        "window", doc="'window': steady once the last window_cycles + 1 cycle means lie within the tolerance (a "
                      "slowly drifting plateau passes it); 'trend': that, and an exponential fit of the latter half "
                      "of the cycle means leaves a change still to come within the tolerance (a drift with no "
                      "levelling-off is extrapolated over three times the run's age; the test must also have held at "
                      "1/1.1 of the run's age), so plateaus and turning points do not stop the run; 'orbit' (the "
                      "modal tier): the structure's state at each period end too: steady when its return per period "
                      "does not grow over the window (by more than 1.1x: the run is not leaving an orbit, a plateau "
                      "on one it is leaving does not stop it) and the trend test holds on the cycle means since it "
                      "last did (docs/transient.md, 'Steady-state stop')")
    window_cycles: int = param(20, ge=2, doc="periods over which the cycle mean may change by the tolerance")
    relative_tolerance: float = param(0.005, gt=0, lt=1, doc="largest relative change of the cycle mean")
    min_cycles: int = param(40, ge=1, doc="periods always run before the test applies")
    speed_floor_rad_per_s: float | None = param(
        None, ge=0, unit="rad/s", doc="a free rotor: the speed scale below which a change counts as noise (a rotor "
                                      "near standstill); default: the scene's (motor: 2 % of the speed a 1 um "
                                      "tangential wave gives), else 0")
    torque_floor_N_m: float | None = param(
        None, ge=0, unit="N m", doc="a held or prescribed rotor: the torque scale below which a change counts as "
                                    "noise; default: the scene's (motor: 2 % of the Coulomb bound), else 0")


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
    start_from: str | None = param(
        None, doc="modal tier: a result directory of an earlier run of the same reduced model (relative to the case "
                  "file); start from its last checkpoint's state (structure and bodies, the clock moved back by "
                  "whole drive periods) instead of initial_state: a warm start along a curve (docs/transient.md, "
                  "'Warm starts')")
    loads: LoadSection = param(default_factory=LoadSection, doc="see [transient.loads]")
    bodies: list[BodySection] = param(default_factory=list, doc="rigid bodies")
    contacts: list[ContactSection] = param(default_factory=list, doc="penalty contacts")
    base_motions: list[BaseMotionSection] = param(
        default_factory=list, doc="prescribed motions of FE facets [[transient.base_motions]]")
    steady_state: SteadyStateSection | None = param(
        None, doc="see [transient.steady_state]: stop at a rotor's steady state (else at end_time_s)")
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
            period = 1.0 / self.drive.frequency_Hz
            drive = (f"one drive period ({period:.6g} s at {self.drive.frequency_Hz:g} Hz) and than "
                     if self.end_time_s < period else "")
            raise CaseError(file, f"{prefix}.end_time_s", f"{self.end_time_s:g} s is shorter than {drive}"
                                                          f"output_interval_s = {self.output_interval_s:g} s")
        names = [b.name for b in self.bodies]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise CaseError(file, f"{prefix}.bodies[{i}].name", f"duplicate rigid body name {name!r}")
        self._check_repeats(file, prefix)
        dims = {len(b.position_m) for b in self.bodies}
        if len(dims) > 1:
            raise CaseError(file, f"{prefix}.bodies", "all bodies need the same number of coordinates")
        for i, contact in enumerate(self.contacts):
            for key, name in contact.bodies():
                if name not in names:
                    known = ", ".join(names) or "none"
                    raise CaseError(file, f"{prefix}.contacts[{i}].{key}",
                                    f"unknown rigid body {name!r} (bodies: {known})")
        self._check_revolution(file, prefix)
        if self.base_motions and self.start_from is not None:
            raise CaseError(file, f"{prefix}.start_from",
                            "base motions ramp up from t = 0: a warm start cannot continue their ramp")
        if self.start_from is not None and not self.start_from.strip():
            raise CaseError(file, f"{prefix}.start_from", "is empty: give a result directory")
        if self.base_motions and self.initial_state == "harmonic":
            raise CaseError(file, f"{prefix}.initial_state",
                            "base motions start from rest (their amplitude ramps up): use 'rest'")
        for i, body in enumerate(self.bodies):
            if body.seat_on is not None:
                self._check_seat(file, f"{prefix}.bodies[{i}].seat_on", body)
        if self.steady_state is not None:
            body = next((b for b in self.bodies if b.name == self.steady_state.body), None)
            if body is None:
                raise CaseError(file, f"{prefix}.steady_state.body",
                                f"unknown rigid body {self.steady_state.body!r} (bodies: {', '.join(names) or 'none'})")
            if not body.rotations:
                raise CaseError(file, f"{prefix}.steady_state.body", f"body {body.name!r} has no rotation to watch")
        contact_names = [c.name for c in self.contacts]
        for i, name in enumerate(contact_names):
            if name in contact_names[:i]:
                raise CaseError(file, f"{prefix}.contacts[{i}].name", f"duplicate contact name {name!r}")

    def _check_repeats(self, file, prefix) -> None:
        """Each base motion's name and facet group once (two motions of one facet group prescribe its DOFs
        twice; overlaps only the mesh shows: app.transient.motions), and no contact twice (the same contact
        under another name presses twice)."""
        motions = self.base_motions
        refuse_repeats([m.name for m in motions], file, lambda i: f"{prefix}.base_motions[{i}].name",
                       "base motion name")
        refuse_repeats([m.facets for m in motions], file, lambda i: f"{prefix}.base_motions[{i}].facets",
                       "prescribed facet group")
        unnamed = [replace(c, name="") for c in self.contacts]
        for i, contact in enumerate(unnamed):
            if contact in unnamed[:i]:
                j = unnamed.index(contact)
                raise CaseError(file, f"{prefix}.contacts[{i}]", f"the same contact as contacts[{j}] "
                                                                 f"({self.contacts[j].name!r}) under another name")

    def _check_revolution(self, file, prefix) -> None:
        """A rotating body's obstacle must be a body of revolution about each rotation axis (every tier moves the
        obstacle with the body's translation only; its spin enters the slip velocity): a plane's normal and a
        cone's axis along the rotation axis (a sphere about its centre is always one)."""
        unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
        for i, contact in enumerate(self.contacts):
            if contact.kind != "surface" or contact.shape == "sphere":
                continue
            j, body = next(((j, b) for j, b in enumerate(self.bodies) if b.name == contact.body), (None, None))
            key = "axis" if contact.shape == "cone" else "normal"
            direction = getattr(contact, key)
            for k, rotation in enumerate(body.rotations if body is not None else ()):
                a = unit.get(rotation.axis)
                if a is None or direction is None or len(direction) != 3:
                    parallel = False
                else:
                    cross = (a[1] * direction[2] - a[2] * direction[1], a[2] * direction[0] - a[0] * direction[2],
                             a[0] * direction[1] - a[1] * direction[0])
                    parallel = sum(c * c for c in cross) < 1e-24
                if not parallel:
                    raise CaseError(file, f"{prefix}.contacts[{i}].{key}",
                                    f"the {contact.shape} obstacle of contact {contact.name!r} is not a body of "
                                    f"revolution about the rotation axis {rotation.axis!r} of body {body.name!r} "
                                    f"({prefix}.bodies[{j}].rotations[{k}].axis)")

    def _check_seat(self, file, key, body) -> None:
        contact = next((c for c in self.contacts if c.name == body.seat_on), None)
        if contact is None:
            names = ", ".join(c.name for c in self.contacts) or "none"
            raise CaseError(file, key, f"unknown contact {body.seat_on!r} (contacts: {names})")
        if contact.kind != "surface" or contact.body != body.name:
            raise CaseError(file, key, f"contact {body.seat_on!r} is not a surface contact of body {body.name!r}")
        free = [] if body.fixed else [k for k, f in enumerate(body.free_axes or [True] * len(body.position_m)) if f]
        if len(free) != 1:
            raise CaseError(file, key, f"seating moves the body along its one free translation axis; {body.name!r} "
                                       f"has {len(free)}")
