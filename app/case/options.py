"""The options table: what each model tier (the case's ``tier``) runs, the sections it needs and the
sections it cannot use, checked when the case is read (before any mesh), so a case that asks a tier for
something it lacks gets one line naming the key, from ``validate`` as from ``run``.

Data only (the case layer builds no engine object): the runner maps each tier to the engine that runs it
(``app.runner.TIER_RUNNERS``). A new tier is one :class:`Tier` entry here and one runner entry there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from app.errors import CaseError


@dataclass(frozen=True)
class Tier:
    """``analyses``: what the tier can run (first ``default_analyses`` when the case lists none);
    ``requires``: sections every case of the tier needs; ``analysis_sections``: sections an
    analysis needs; ``foreign``: sections of other tiers, an error here (they would be ignored)."""

    name: str
    doc: str
    analyses: tuple[str, ...]
    default_analyses: tuple[str, ...]
    requires: tuple[str, ...] = ()
    analysis_sections: dict[str, tuple[str, ...]] = field(default_factory=dict)
    foreign: tuple[str, ...] = ()


TIERS: dict[str, Tier] = {
    "fe": Tier(
        "fe", "full finite-element model (dolfinx)",
        analyses=("modal", "harmonic", "circuit", "transient"), default_analyses=("modal",),
        requires=("geometry",),
        analysis_sections={"transient": ("transient",)},
        foreign=("lumped",)),
    "modal": Tier(
        "modal", "modal-reduced FE: the transient on a Craig-Bampton basis (docs/reduced.md); the "
                 "frequency-domain analyses on the FE model",
        analyses=("modal", "harmonic", "circuit", "transient"), default_analyses=("transient",),
        requires=("geometry",),
        analysis_sections={"transient": ("transient",)},
        foreign=("lumped",)),
    "lumped": Tier(
        "lumped", "lumped-parameter models: [lumped] model = 'impact_chain' (the drill: transducer mode + rigid "
                  "bodies + Kelvin-Voigt contacts) or 'friction_drive' (the motor: wave mode + friction-drive law)",
        analyses=("lumped",), default_analyses=("lumped",),
        requires=("lumped",),
        foreign=("geometry", "materials", "regions", "electrodes", "supports", "points", "damping", "modal",
                 "harmonic", "circuit", "reduction", "output", "transient")),
}


def foreign_section(tier_name, section: str, file: str) -> CaseError | None:
    """The error for a section the case file gives that tier ``tier_name`` does not read (None if it reads
    it, or the tier is unknown)."""
    tier = TIERS.get(tier_name) if isinstance(tier_name, str) else None
    if tier is None or section not in tier.foreign:
        return None
    owners = [t.name for t in TIERS.values() if section not in t.foreign]
    return CaseError(file, section, f"not a section of tier {tier.name!r} (it belongs to tier "
                                    f"{' or '.join(map(repr, owners))})")


def check_tier(case, file: str, written=None) -> None:
    """Tier-level input checks of a loaded case (one CaseError naming the key); ``written``: the top-level
    keys the case file (with its overrides) gives, the sections checked against the tier's foreign ones
    (default: the sections that are set)."""
    tier = TIERS.get(case.tier)
    if tier is None:
        raise CaseError(file, "tier", f"unknown tier {case.tier!r} (tiers: {', '.join(TIERS)})")
    for i, analysis in enumerate(case.analyses or ()):
        if analysis not in tier.analyses:
            raise CaseError(file, f"analyses[{i}]", f"{analysis!r} is not an analysis of tier {tier.name!r} "
                                                    f"(it runs: {', '.join(tier.analyses)})")
    for section in tier.requires:
        if getattr(case, section) is None:
            raise CaseError(file, section, f"section required for tier = {tier.name!r}")
    for analysis in case.analyses or ():
        for section in tier.analysis_sections.get(analysis, ()):
            if getattr(case, section) is None:
                raise CaseError(file, section, f"section required by analysis {analysis!r}")
    for section in tier.foreign:
        if (section in written) if written is not None else getattr(case, section) is not None:
            raise foreign_section(tier.name, section, file)
    if case.output.contact_pressure:
        _check_contact_pressure(case, file)
    if case.tier == "modal" and case.transient is not None and case.reduction.interface == "nodes" \
            and case.reduction.site_displacement == "interface":
        for i, contact in enumerate(case.transient.contacts):
            if getattr(contact, "sample_rings", 1) > 1:
                raise CaseError(file, f"transient.contacts[{i}].sample_rings",
                                "rings across the band see one displacement with the nodes interface: set "
                                'reduction.interface = "band" or reduction.site_displacement = "field"')
    _check_surgery(case, file)
    steady = case.transient.steady_state if case.transient is not None else None
    if steady is not None and steady.rule == "orbit" and case.tier != "modal":
        raise CaseError(file, "transient.steady_state.rule",
                        f"'orbit' compares the reduced structure's state period to period: the modal tier's only "
                        f"(this case runs tier {case.tier!r}; use 'trend')")
    if case.transient is not None and case.transient.start_from is not None and case.tier != "modal":
        raise CaseError(file, "transient.start_from", f"warm starts are offered by the modal tier only (this case "
                                                      f"runs tier {case.tier!r})")


def _check_contact_pressure(case, file: str) -> None:
    """``output.contact_pressure`` is the transient pressure of the surface contacts, in the FE tier (a field on
    the mesh) and the modal tier (at its contact sites, a point cloud companion of the fields)."""
    if case.tier not in ("fe", "modal") or "transient" not in (case.analyses or ()):
        raise CaseError(file, "output.contact_pressure", "is written by the transient analysis of the FE and modal "
                                                         "tiers only")
    if not any(c.kind == "surface" for c in case.transient.contacts):
        raise CaseError(file, "output.contact_pressure", "the case has no surface contact ([[transient.contacts]] "
                                                         "of kind 'surface') to write the pressure of")


def _check_surgery(case, file: str) -> None:
    """``reduction.surgery``, ``site_motion``, ``wave_scale`` (app/reduced/surgery.py): the modal tier's transient,
    electrodes only as inputs, a prescribed wave driven in two phases, planar sites on cone contacts."""
    red = case.reduction
    given = [(key, value) for key, value, default in (("surgery", red.surgery, "none"),
                                                      ("site_motion", red.site_motion, "full"),
                                                      ("wave_scale", red.wave_scale, 1.0)) if value != default]
    if not given:
        return
    key = f"reduction.{given[0][0]}"
    if case.tier != "modal" or case.transient is None or "transient" not in (case.analyses or ()):
        raise CaseError(file, key, "acts on the modal tier's transient only")
    if red.wave_scale != 1.0 and red.surgery not in ("rigid_wave", "travelling_wave"):
        raise CaseError(file, "reduction.wave_scale", "scales the prescribed wave of surgery = 'rigid_wave' or "
                                                      "'travelling_wave' only")
    if red.surgery != "none" and case.transient.base_motions:
        raise CaseError(file, "reduction.surgery", "keeps electrode inputs only: remove [[transient.base_motions]]")
    if red.surgery in ("rigid_wave", "travelling_wave"):
        phases = [math.radians(e.phase_deg) for e in case.electrodes.values() if e.kind == "voltage"]
        spans = any(abs(math.sin(a - b)) > 1e-6 for a in phases for b in phases)
        if not spans:
            raise CaseError(file, "reduction.surgery", f"{red.surgery!r} needs voltage electrodes driven in two "
                                                       "independent phases (a travelling wave)")
    if red.surgery == "travelling_wave" and sum(c.kind == "surface" and c.shape == "cone"
                                                for c in case.transient.contacts) != 1:
        raise CaseError(file, "reduction.surgery", "'travelling_wave' takes the wave round one cone contact: the case "
                                                   "needs exactly one ([[transient.contacts]] with shape 'cone')")
    if red.site_motion == "planar":
        if case.geometry.model != "3d":
            raise CaseError(file, "reduction.site_motion", "'planar' needs a 3D model")
        for i, contact in enumerate(case.transient.contacts):
            if contact.kind == "surface" and contact.shape != "cone":
                raise CaseError(file, f"transient.contacts[{i}].shape",
                                "reduction.site_motion = 'planar' drops a cone's meridional motion: cone contacts only")
