"""The case schema: every key a TOML case may hold, its type, bounds, unit and default.

Defaults live here and only here. ``load_case`` turns a TOML file (plus ``--set`` overrides) into a
validated :class:`Case` before any dolfinx object is built; checks that need the mesh (missing
facet or cell groups) happen in :mod:`app.fe.problem` and raise the same :class:`CaseError`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from app.case.loader import apply_overrides, read_toml
from app.case.validate import from_dict, param, refuse_repeats
from app.errors import CaseError
from app.materials import Material, resolve

ModelKind = Literal["axisymmetric", "3d", "plane_strain", "fourier"]
Analysis = Literal["modal", "harmonic", "circuit", "transient", "lumped"]
# derived fields of the FE-based analyses (app/fe/derived.py DERIVED_FIELDS; tests/test_derived_fields.py checks the
# two lists agree)
DerivedField = Literal["strain", "stress", "von_mises", "principal_stress", "electric_field", "electric_displacement"]
TagRef = str | int


@dataclass(frozen=True)
class GeometrySection:
    model: ModelKind = param(
        "axisymmetric", doc="axisymmetric (r, z), 3d (x, y, z), plane_strain (x, z), or fourier: a body of revolution "
                            "about z meshed in (r, z) whose fields are one circumferential order n, exact in theta "
                            "(u_r, u_z, phi ~ cos n theta, u_theta ~ sin n theta; modal only; docs/fourier.md)")
    builder: Literal["bar", "disc", "ring", "transducer", "stator", "thin_ring"] | None = param(
        None, doc="gmsh builder to use")
    parameters: dict[str, Any] = param(default_factory=dict, doc="builder parameters (see docs)")
    mesh_file: str | None = param(None, doc=".msh file, relative to the case file")
    degree: int = param(2, ge=1, le=3, doc="Lagrange degree of u and phi")
    thickness_m: float = param(1.0, gt=0, doc="out-of-plane thickness for plane_strain")
    circumferential_order: int | None = param(
        None, ge=0, le=1000, doc="the order n of a model = 'fourier' (required there, and only there)")
    quadrature_degree: int | None = param(
        None, ge=1, le=30, doc="quadrature degree of the volume forms; default: UFL's estimate, which for a "
                               "radially poled 3D region (a rotation by x / r in every material tensor) is 22 on "
                               "straight and 37 on curved cells, most of the assembly time (docs/motor-stator.md)")

    def check(self, file, prefix):
        if (self.builder is None) == (self.mesh_file is None):
            raise CaseError(file, f"{prefix}.builder", "give exactly one of builder or mesh_file")
        if (self.model == "fourier") != (self.circumferential_order is not None):
            raise CaseError(file, f"{prefix}.circumferential_order",
                            "required for model = 'fourier'" if self.model == "fourier"
                            else f"only for model = 'fourier', not {self.model!r}")


@dataclass(frozen=True)
class Region:
    cells: TagRef = param(doc="cell group name or tag")
    material: str = param(doc="name of a [materials.*] entry")
    poling: Literal["+x", "-x", "+y", "-y", "+z", "-z", "radial", "-radial"] | list[float] = param(
        "+z", doc="poling direction of a piezoelectric material (global axes; radial about z)")


@dataclass(frozen=True)
class Electrode:
    facets: list[TagRef] = param(
        doc="facet group names or tags, each in one electrode; electrodes meeting at an edge (sharing nodes) "
            "must both be ground (an electrode is an equipotential surface)")
    kind: Literal["ground", "voltage", "floating"] = param(doc="0 V, driven, or equipotential with zero charge")
    amplitude_V: float | None = param(
        None, ge=0, unit="V", doc="drive amplitude of this electrode (kind 'voltage'); default: the analysis' "
                                  "voltage_V. A target-amplitude solve scales every electrode by one factor")
    phase_deg: float = param(
        0.0, unit="deg", doc="drive phase of this electrode (kind 'voltage'): U(t) = A cos(omega t + phase), "
                             "phasor A exp(i phase)")

    def check(self, file, prefix):
        refuse_repeats(self.facets, file, lambda j: f"{prefix}.facets[{j}]", "facet group")
        if self.kind != "voltage":
            for key, unset in (("amplitude_V", self.amplitude_V is None), ("phase_deg", self.phase_deg == 0.0)):
                if not unset:
                    raise CaseError(file, f"{prefix}.{key}",
                                    f"only for electrodes of kind 'voltage', not {self.kind!r}")


@dataclass(frozen=True)
class Support:
    facets: list[TagRef] = param()
    components: list[Literal["x", "y", "z", "r"]] = param(doc="displacement components held at 0")

    def check(self, file, prefix):
        refuse_repeats(self.facets, file, lambda j: f"{prefix}.facets[{j}]", "facet group")
        refuse_repeats(self.components, file, lambda j: f"{prefix}.components[{j}]", "component")


@dataclass(frozen=True)
class Point:
    coordinates_m: list[float] = param()
    component: Literal["x", "y", "z", "r"] = param("z", doc="displacement component reported")


@dataclass(frozen=True)
class DampingSection:
    alpha_per_s: float = param(0.0, ge=0, doc="mass-proportional Rayleigh alpha")
    beta_s: float = param(0.0, ge=0, doc="global stiffness-proportional Rayleigh beta")
    material_quality: bool = param(True, doc="add beta_j = 1/(omega Q_m,j) per material")
    reference_frequency_Hz: float | None = param(None, gt=0, doc="omega in beta_j; default: working mode")


@dataclass(frozen=True)
class ModeIdentification:
    """Fourier identification of bodies of revolution about z (see app.modeid)."""

    circle_radius_m: float = param(gt=0, doc="circle sampled for the circumferential order n")
    circle_height_m: float = param(doc="z of that circle")
    n_circle_points: int = param(64, ge=8)
    line_radius_m: float | None = param(None, gt=0, doc="generatrix sampled for the axial order m")
    line_z_start_m: float | None = param(None)
    line_z_stop_m: float | None = param(None)
    n_line_points: int = param(24, ge=3)
    working_order: list[int] | None = param(None, doc="[m, n]: the working mode is the mode of this order "
                                                      "nearest the target")

    def check(self, file, prefix):
        if self.line_radius_m is not None and (self.line_z_start_m is None or self.line_z_stop_m is None):
            raise CaseError(file, f"{prefix}.line_z_start_m", "give line_z_start_m and line_z_stop_m with "
                                                               "line_radius_m")
        if self.working_order is not None and len(self.working_order) != 2:
            raise CaseError(file, f"{prefix}.working_order", "needs two integers [m, n]")
        if self.working_order is not None and self.line_radius_m is None:
            raise CaseError(file, f"{prefix}.working_order", "needs the generatrix (line_radius_m) for m")


@dataclass(frozen=True)
class ContactForceSection:
    """The working mode's modal force referred to a contact circle of a body of revolution (app.modal,
    docs/motor-stator.md): F_m = 2 zeta k_m W, W the free normal amplitude there at resonance."""

    circle_radius_m: float = param(gt=0, unit="m", doc="contact circle (inside the mesh)")
    circle_height_m: float = param(unit="m", doc="z of that circle")
    normal_rz: list[float] = param(doc="outward normal (n_r, n_z) of the contact surface there: the normal "
                                       "displacement w = u . n, and N = P / |n_z| for an axial preload P")
    order: int = param(ge=1, doc="circumferential order n of the wave")
    n_points: int = param(64, ge=8)
    preloads_N: list[float] = param(
        default_factory=list, unit="N", doc="axial preloads P of a rotor on that surface: the summary gives the "
                                            "normal force N = P / |n_z| each needs and the ratio N / F_m")
    voltage_V: float = param(1.0, gt=0, unit="V", doc="amplitude of driven electrodes without amplitude_V")

    def check(self, file, prefix):
        if len(self.normal_rz) != 2 or not self.normal_rz[1]:
            raise CaseError(file, f"{prefix}.normal_rz", "needs two numbers (n_r, n_z), n_z not zero")
        if any(p <= 0 for p in self.preloads_N):
            raise CaseError(file, f"{prefix}.preloads_N", "every preload must be > 0")


@dataclass(frozen=True)
class CyclicSection:
    """Modes of one harmonic index of a cyclically symmetric body from the mesh of one sector (app/fe/cyclic.py)."""

    sector_deg: float = param(gt=0, le=180, unit="deg", doc="the sector's angle (the mesh spans -sector/2 .. "
                                                            "+sector/2 about z); 360 / sector_deg sectors")
    order: int = param(ge=0, doc="harmonic index k: modes of circumferential orders k, N - k, N + k, ...")

    def check(self, file, prefix):
        sectors = 360.0 / self.sector_deg
        if abs(sectors - round(sectors)) > 1e-9:
            raise CaseError(file, f"{prefix}.sector_deg", "must divide 360 deg")
        if self.order > round(sectors) // 2:
            raise CaseError(file, f"{prefix}.order", f"must be at most {round(sectors) // 2} (half the sectors)")


@dataclass(frozen=True)
class ModalSection:
    target_frequency_Hz: float = param(gt=0, unit="Hz", doc="shift of the shift-invert transform")
    n_modes: int = param(6, ge=1, le=1000, doc="number of modes (SLEPc nev) per electrical state")
    electrical: Literal["short", "open", "both"] = param("both")
    rigid_cutoff_Hz: float = param(10.0, ge=0, doc="modes below are rigid-body modes and dropped")
    working_mode: Literal["nearest", "coupling"] = param(
        "coupling", doc="nearest to target, or the most strongly coupled of the modes found")
    identify: ModeIdentification | None = param(None, doc="mode orders (m, n), partners and splits")
    cyclic: CyclicSection | None = param(
        None, doc="the mesh is one sector of a cyclically symmetric body: modes of one harmonic index (serial, "
                  "short circuit)")
    contact_force: ContactForceSection | None = param(
        None, doc="F_m, the working mode's (and its partner's) modal force per volt at a contact circle, and "
                  "N / F_m for given preloads")

    def check(self, file, prefix):
        if self.cyclic is not None:
            for key in ("identify", "contact_force"):
                if getattr(self, key) is not None:
                    raise CaseError(file, f"{prefix}.{key}", "needs the whole body, not one sector (modal.cyclic)")


@dataclass(frozen=True)
class TargetAmplitude:
    point: str = param()
    amplitude_m: float = param(gt=0, unit="m")


@dataclass(frozen=True)
class TravellingWaveSection:
    """Wave measures round a circle of a body of revolution about z (see app.modeid.travelling_wave)."""

    circle_radius_m: float = param(gt=0)
    circle_height_m: float = param()
    normal_rz: list[float] = param(doc="outward surface normal (n_r, n_z) there, e.g. the inclined face")
    order: int = param(ge=1, doc="circumferential order n of the wave")
    n_points: int = param(64, ge=8)
    frequency_Hz: float | None = param(None, gt=0, doc="default: the modal working mode, else the |Y| peak")
    animation_frames: int = param(24, ge=0, doc="XDMF frames over one period (0: none)")
    balance: str | None = param(
        None, doc="driven electrode whose amplitude and phase are trimmed so that the order-n part travelling "
                  "against the wave vanishes (a two-phase driver's balance); the measures, the exported wave and "
                  "the wave's admittances are then the balanced drive's, the nominal drive's measures are kept too")
    balance_with: list[str] = param(
        default_factory=list, doc="further driven electrodes trimmed by the same factor as balance: the other "
                                  "segments of the trimmed phase (e.g. Bm, driven in antiphase with B)")

    def check(self, file, prefix):
        if len(self.normal_rz) != 2 or not any(self.normal_rz):
            raise CaseError(file, f"{prefix}.normal_rz", "needs two numbers, not both zero")
        if self.balance_with and self.balance is None:
            raise CaseError(file, f"{prefix}.balance_with", "needs balance (the electrode the others follow)")


@dataclass(frozen=True)
class HarmonicSection:
    f_start_Hz: float | None = param(None, gt=0, doc="default: around the modal f_r, f_a")
    f_stop_Hz: float | None = param(None, gt=0)
    n_points: int = param(41, ge=2, le=100_000, doc="frequencies of the sweep")
    voltage_V: float = param(1.0, gt=0, doc="drive amplitude on voltage electrodes")
    refine_extrema: bool = param(True, doc="locate |Y| peak and trough by golden-section search")
    target: TargetAmplitude | None = None
    wave: TravellingWaveSection | None = param(None, doc="travelling-wave measures at a circle")

    def check(self, file, prefix):
        if (self.f_start_Hz is None) != (self.f_stop_Hz is None):
            raise CaseError(file, f"{prefix}.f_stop_Hz", "give both f_start_Hz and f_stop_Hz or neither")
        if self.f_start_Hz is not None and self.f_stop_Hz <= self.f_start_Hz:
            raise CaseError(file, f"{prefix}.f_stop_Hz", "must be greater than f_start_Hz")


@dataclass(frozen=True)
class CircuitSection:
    point: str = param(doc="named point the 1-DOF model is referred to")


@dataclass(frozen=True)
class ReductionSection:
    """Basis of the modal tier (Craig-Bampton, docs/reduced.md): the interface DOFs are the FE nodes
    the case's contacts touch and every driven electrode; this chooses the fixed-interface modes."""

    n_modes: int | None = param(None, ge=1, le=2000, doc="number of fixed-interface modes (overrides the cutoff)")
    cutoff_Hz: float | None = param(None, gt=0, unit="Hz", doc="keep every fixed-interface mode below this frequency")
    cutoff_factor: float = param(
        20.0, gt=1, doc="default cutoff = factor x the transient drive frequency (when neither key is given)")
    interface_nodes: int | None = param(
        None, ge=1, le=4096, doc="nodes of each sampled surface kept as interface coordinates (all their displacement "
                                 "DOFs): default all of them (sampling 'nodes'), 64 evenly round the contact circle "
                                 "(sampling 'ring'); fewer: a smaller basis (docs/reduced.md: convergence)")
    interface: Literal["nodes", "band"] = param(
        "nodes", doc="a ring-sampled contact's interface coordinates: the displacements of its interface nodes (each "
                     "carries the sites' forces as a point load, whose local compliance grows as the mesh is refined), "
                     "or 'band': the same stations, with every node of the contact band following their cubic-in-angle "
                     "interpolation (the band moves as a ring, the sites' forces spread over it: docs/reduced.md, "
                     "'The band interface')")
    site_displacement: Literal["interface", "field"] = param(
        "interface", doc="a ring-sampled site's displacement: interpolated from the interface nodes (cubic in angle; "
                         "its force acts on interface coordinates only), or the reduced field at the point")
    enrich_near_Hz: float | None = param(
        None, gt=0, unit="Hz", doc="frequency the enrichment modes are nearest (default: the transient drive's; set it "
                                   "to keep one reduced model over a frequency sweep)")
    enrich_modes: int = param(
        0, ge=0, le=16, doc="add the full FE model's modes nearest the drive frequency (electrodes held, interface "
                            "free) to the basis, so its resonance there is the FE model's exactly: 2 for the motor's "
                            "F(1,4) pair (a drive within a few bandwidths of it makes the wave steep in the detuning)")
    surgery: Literal["none", "modal_pair", "rigid_wave", "travelling_wave"] = param(
        "none", doc="model surgery for a chain of controlled runs (docs/motor-chain.md, app/reduced/surgery.py): "
                    "'none' runs the reduced model as built; 'modal_pair' keeps only the two modes nearest the "
                    "drive (and the electrodes' static response), loaded by the contacts; 'rigid_wave' prescribes "
                    "that pair's free steady wave at the contact sites (a rigid stator surface: the contact forces "
                    "load nothing), its amplitude wave_scale x the free one; 'travelling_wave' the same reduced to "
                    "its travelling component round the (one) cone contact: uniform amplitude, one order, one "
                    "direction (the friction-drive law's wave)")
    site_motion: Literal["full", "planar"] = param(
        "full", doc="the contact sites' motion: 'full', or 'planar': each cone contact's sites moving along the cone's "
                    "normal and circumference only (the meridional component dropped: the friction-drive law's "
                    "kinematics)")
    wave_scale: float = param(
        1.0, gt=0, doc="surgery = 'rigid_wave' or 'travelling_wave': the prescribed wave's amplitude over the free "
                       "steady wave's (set it so the normal wave equals a full run's at the same operating point)")


@dataclass(frozen=True)
class OutputSection:
    fields: bool = param(True, doc="write XDMF mode shapes / fields")
    plots: bool = param(True, doc="write PNG plots")
    derived: list[DerivedField] = param(
        default_factory=lambda: ["von_mises", "principal_stress", "electric_field"],
        doc="derived fields added to the FE field files (modes, harmonic response, FE transient): strain [-], stress "
            "[Pa], von_mises [Pa], principal_stress [Pa], electric_field [V/m], electric_displacement [C/m^2]; "
            "region-wise averaged vertex values (docs/fields.md); [] for none")
    energies: bool = param(
        False, doc="transient: energy columns (kinetic, strain, rigid kinetic, contact penalty, damping loss) and the "
                   "electrodes' charges, for an energy balance")
    contact_sites: bool = param(
        False, doc="transient: per output interval and per sample point of every sampled surface contact, the mean "
                   "pressure and the fractions of time closed, sticking and slipping either way, the slip speed's "
                   "parts along e1 and e2 and the friction power's, the first harmonics of the pressure and the normal "
                   "displacement, and the contact against the wave's phase per ring (tables '<contact>_sites_*' in "
                   "transient.h5; app/contact/tables.py)")
    series_csv: bool = param(
        False, doc="transient and lumped: the time series also as transient.csv (a header line of names with units, "
                   "one column per component, the rows of transient.h5; docs/transient.md)")
    mode_shape_amplitude_m: float = param(
        1e-3, gt=0, unit="m", doc="mode-shape files: each mode written scaled so its largest vertex displacement is "
                                  "this (Warp By Vector at scale 1 shows it); the factor applied to the "
                                  "mass-normalised shape is in the file (docs/summary.md)")
    contact_pressure: bool = param(
        False, doc="transient, FE and modal tiers: the normal contact pressure of every surface contact, the "
                   "solver's penalty law: FE tier at the vertices of its facets (field 'contact_pressure_Pa' of "
                   "transient_fields.xdmf, zero off the contact surfaces), modal tier at its contact sites (the same "
                   "name in the point cloud transient_contact_sites.xdmf, moving with the structure, with each "
                   "site's area); each step's peak ('<contact>_peak_pressure_Pa' in transient.h5) and the "
                   "run's (results.transient.contacts.<contact>.max_pressure_Pa) in both")
    field_phases: int | None = param(
        None, ge=1, doc="transient fields: frames per drive period (transient.drive.frequency_Hz) in each burst, "
                        "evenly spaced in phase; a burst spans one period (default 8)")
    field_interval_periods: float | None = param(
        None, gt=0, doc="transient fields: drive periods from one burst's start to the next (at least 1 when "
                        "field_phases > 1); default: field_phases x transient.output_interval_s in whole periods "
                        "(as many frames as one per output_interval_s, none aliased to one phase)")
    field_burst_times_s: list[float] | None = param(
        None, unit="s", doc="transient fields: bursts start at these times (increasing, before end_time_s, one "
                            "period apart) instead of every field_interval_periods")

    def check(self, file, prefix):
        for i, name in enumerate(self.derived):
            if name in self.derived[:i]:
                raise CaseError(file, f"{prefix}.derived[{i}]", f"{name!r} is listed twice")

    def check_frames(self, case, file) -> None:
        """Cross-key rules of the phase-locked field output (app/transient/fields.py frame_schedule)."""
        given = [k for k in ("field_phases", "field_interval_periods", "field_burst_times_s")
                 if getattr(self, k) is not None]
        if not given:
            return
        if case.transient is None:
            raise CaseError(file, f"output.{given[0]}", "sets the transient field output: the case has no [transient]")
        if "transient" not in (case.analyses or ()):
            return                      # the case's transient is not run this time (e.g. --set analyses=["modal"])
        if self.field_interval_periods is not None and self.field_burst_times_s is not None:
            raise CaseError(file, "output.field_burst_times_s", "give field_burst_times_s or "
                                                                "field_interval_periods, not both")
        phases = self.field_phases or 8
        period = 1.0 / case.transient.drive.frequency_Hz
        if phases > 1 and self.field_interval_periods is not None and self.field_interval_periods < 1:
            raise CaseError(file, "output.field_interval_periods",
                            f"{self.field_interval_periods:g} periods is shorter than a burst (one period of "
                            f"field_phases = {phases} frames)")
        steps = case.transient.steps
        largest = max(steps.open_s, steps.closed_s, steps.change_s)
        if phases > 1 and period / phases < largest * (1 - 1e-9):
            raise CaseError(file, "output.field_phases", f"{phases} frames per period are {period / phases:.4g} s "
                                                         f"apart, less than the time step {largest:g} s")
        times = self.field_burst_times_s
        for i, t in enumerate(times or ()):
            if not 0 <= t < case.transient.end_time_s:
                raise CaseError(file, f"output.field_burst_times_s[{i}]",
                                f"{t:g} s is outside the run [0, end_time_s = {case.transient.end_time_s:g} s)")
            if i and t < times[i - 1] + (period if phases > 1 else 0.0) * (1 - 1e-9):
                raise CaseError(file, f"output.field_burst_times_s[{i}]",
                                f"{t:g} s is not one drive period ({period:.4g} s) after the previous burst")


@dataclass(frozen=True)
class Case:
    tier: Literal["fe", "modal", "lumped"] = param(
        "fe", doc="model tier: full FE, modal-reduced FE (transient) or lumped")
    title: str = param("", doc="free text shown in the log")
    scene: str | None = param(
        None, doc="scene report with its own statistics and plots (app/scenes/): percussion-drill")
    analyses: list[Analysis] | None = param(
        None, doc="analyses to run: modal, harmonic, circuit, transient (tier fe; default modal) or lumped")
    geometry: GeometrySection | None = param(None, doc="mesh source (tier fe)")
    materials: dict[str, Material] = param(default_factory=dict, doc="named materials")
    regions: list[Region] = param(default_factory=list, doc="material and poling per cell group")
    electrodes: dict[str, Electrode] = param(default_factory=dict, doc="named electrodes")
    supports: list[Support] = param(default_factory=list, doc="fixed displacement components")
    points: dict[str, Point] = param(default_factory=dict, doc="named points for results")
    damping: DampingSection = param(default_factory=DampingSection, doc="see [damping]")
    modal: ModalSection | None = param(None, doc="see [modal]")
    harmonic: HarmonicSection | None = param(None, doc="see [harmonic]")
    circuit: CircuitSection | None = param(None, doc="see [circuit]")
    reduction: ReductionSection = param(default_factory=ReductionSection, doc="see [reduction] (tier modal)")
    output: OutputSection = param(default_factory=OutputSection, doc="see [output]")
    lumped: Any = param(None, doc="see [lumped] (tier lumped)")
    transient: Any = param(None, doc="see [transient]")
    source: str = param("", doc="set by the loader: path of the case file")

    def check(self, file, prefix):
        if self.tier in ("fe", "modal"):
            if self.geometry is None:
                raise CaseError(file, "geometry", f"required for tier = {self.tier!r}")
            if not self.regions:
                raise CaseError(file, "regions", f"at least one region is required for tier = {self.tier!r}")
            for i, region in enumerate(self.regions):
                if region.material not in self.materials:
                    raise CaseError(file, f"regions[{i}].material",
                                    f"unknown material {region.material!r}; defined: {', '.join(self.materials)}")
                if isinstance(region.poling, list) and (len(region.poling) != 3 or not any(region.poling)):
                    raise CaseError(file, f"regions[{i}].poling", "a poling vector needs 3 non-zero-norm entries")
            refuse_repeats([r.cells for r in self.regions], file, lambda i: f"regions[{i}].cells", "cell group")
        self._check_electrode_facets(file)
        self._check_support_facets(file)
        from app.case.options import TIERS

        runnable = TIERS[self.tier].analyses
        for i, analysis in enumerate(self.analyses or []):
            if analysis not in runnable:
                raise CaseError(file, f"analyses[{i}]", f"tier {self.tier!r} cannot run analysis {analysis!r} "
                                                        f"(it runs: {', '.join(runnable)})")
        if self.analyses is not None and len(set(self.analyses)) != len(self.analyses):
            raise CaseError(file, "analyses", "lists an analysis twice")
        if self.analyses == []:
            raise CaseError(file, "analyses", "lists no analysis")
        analyses = set(self.analyses or [])
        if "circuit" in analyses and "modal" not in analyses:
            raise CaseError(file, "analyses", "analysis 'circuit' needs the working mode: add 'modal'")
        if ("harmonic" in analyses and "modal" not in analyses and self.harmonic is not None
                and self.harmonic.f_start_Hz is None):
            raise CaseError(file, "harmonic.f_start_Hz", "give f_start_Hz and f_stop_Hz, or add 'modal' to "
                                                         "analyses (the default range is around the modal f_r, f_a)")
        driven = any(e.kind == "voltage" for e in self.electrodes.values())
        for analysis in ("harmonic", "circuit"):
            if analysis in analyses and not driven:
                raise CaseError(file, "electrodes", f"analysis {analysis!r} needs an electrode of kind 'voltage'")
        needs = {"modal": ("modal",), "harmonic": ("harmonic",), "circuit": ("modal", "harmonic", "circuit")}
        for analysis in self.analyses or []:
            for section in needs.get(analysis, ()):
                if getattr(self, section) is None:
                    raise CaseError(file, section, f"section required by analysis {analysis!r}")
        balance = self.harmonic.wave.balance if self.harmonic and self.harmonic.wave else None
        if balance is not None:
            voltage = [name for name, e in self.electrodes.items() if e.kind == "voltage"]
            if balance not in voltage or len(voltage) < 2:
                raise CaseError(file, "harmonic.wave.balance", "needs one of two or more electrodes of kind "
                                                               f"'voltage' (they are: {', '.join(voltage)})")
        if self.harmonic and self.harmonic.target and self.harmonic.target.point not in self.points:
            raise CaseError(file, "harmonic.target.point", f"unknown point {self.harmonic.target.point!r}")
        if self.circuit and self.circuit.point not in self.points:
            raise CaseError(file, "circuit.point", f"unknown point {self.circuit.point!r}")

    def _check_electrode_facets(self, file) -> None:
        """An electrode is an equipotential surface: a facet group belongs to one electrode at most (by name
        here; by tag and by shared potential DOFs where the mesh tells, app.fe.model)."""
        owner = {}
        for name, electrode in self.electrodes.items():
            for j, ref in enumerate(electrode.facets):
                other = owner.setdefault(repr(ref), name)
                if other != name:
                    raise CaseError(file, f"electrodes.{name}.facets[{j}]",
                                    f"facet group {ref!r} is also in electrode {other!r} (a facet belongs to one "
                                    "electrode at most)")

    def _check_support_facets(self, file) -> None:
        """A displacement component of a facet group is held by one support (two supports may hold different
        components of the same facets)."""
        held = {}
        for i, support in enumerate(self.supports):
            for j, ref in enumerate(support.facets):
                for component in support.components:
                    other = held.setdefault((repr(ref), component), i)
                    if other != i:
                        raise CaseError(file, f"supports[{i}].facets[{j}]",
                                        f"component {component!r} of facet group {ref!r} is already held by "
                                        f"supports[{other}]")


def _section_types():
    """The sections with a module of their own in app/case/ (typed ``Any`` in :class:`Case`)."""
    from app.case.lumped import LumpedSection
    from app.case.transient import TransientSection

    return {"lumped": LumpedSection, "transient": TransientSection}


def _explained(exc: CaseError, in_file: dict, written: set, tier) -> CaseError:
    """A section's error that points the wrong way, pointed right: a section the case's tier does not read
    is named as such (not by a key missing from it), and a key missing from a section that only the --set
    overrides made says so."""
    from app.case.options import foreign_section

    section = str(exc.key or "").split(".")[0].split("[")[0]
    if section not in written:
        return exc
    foreign = foreign_section(tier, section, exc.file)
    if foreign is not None:
        return foreign
    if section not in in_file and exc.message == "required key is missing":
        return CaseError(exc.file, exc.key, f"required key is missing (the case file has no [{section}] section: "
                                            "the overrides made one)")
    return exc


def load_case(path: str | Path, overrides: list[str] | None = None) -> Case:
    """Read, override and validate a case file into a :class:`Case`."""
    path = Path(path)
    file = str(path)
    in_file = read_toml(path)
    raw = apply_overrides(in_file, overrides)
    written = set(raw)
    if "source" in raw:
        raise CaseError(file, "source", "is set by piezodyn, not by the case file")
    sections = _section_types()
    extra = {}
    try:
        for name, cls in sections.items():
            if name in raw:
                if name == "lumped":        # the lumped tier's models have tables of their own
                    from app.case.lumped import lumped_section_type

                    cls = lumped_section_type(raw[name], file)
                extra[name] = from_dict(cls, raw.pop(name), file, name)
        case = from_dict(Case, raw, file)
    except CaseError as exc:
        raise _explained(exc, in_file, written, raw.get("tier", Case.tier)) from None
    materials = {name: resolve(m, file, f"materials.{name}") for name, m in case.materials.items()}
    from app.case.options import TIERS, check_tier

    default = list(TIERS[case.tier].default_analyses) if case.tier in TIERS else []
    analyses = case.analyses if case.analyses is not None else default
    case = replace(case, materials=materials, analyses=analyses, source=str(path.resolve()), **extra)
    check_tier(case, file, written)
    case.output.check_frames(case, file)
    _check_drive_lock(case, file)
    return case


def _check_drive_lock(case: Case, file: str) -> None:
    """A drive locked to the resonance needs something driven (a cross-section rule: electrodes and transient)."""
    if case.transient is None or case.transient.drive.lock != "resonance":
        return
    from app.drive import is_driven

    if not is_driven(case):
        raise CaseError(file, "transient.drive.lock", "locks the drive to the resonance, but the transient drives "
                                                      "nothing (no electrode of kind 'voltage' with a voltage, no "
                                                      "tip amplitude, no base motion)")
