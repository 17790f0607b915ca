"""Input rules of a motor case in the modal tier (a cone contact on a rotor): checked when the case is read,
before any mesh, so ``validate`` and ``run`` refuse the same inputs with one line naming the key."""

from __future__ import annotations

from app.errors import CaseError


def is_motor_case(case) -> bool:
    """A transient whose contact is a cone on a rotor: the modal tier runs it with this module."""
    cfg = case.transient
    return cfg is not None and any(c.kind == "surface" and c.shape == "cone" for c in cfg.contacts)


def check_motor_case(case, file: str) -> None:
    """The modal tier's motor needs exactly one cone contact on one rotor turning about the cone's z axis,
    translating along it only; Newmark time stepping. One CaseError naming the key otherwise."""
    cfg = case.transient
    key = "transient"
    if len(cfg.contacts) != 1:
        raise CaseError(file, f"{key}.contacts", "the modal tier's motor has exactly one (cone) contact")
    contact = cfg.contacts[0]
    if contact.axis is None or [abs(a) for a in contact.axis] != [0.0, 0.0, 1.0]:
        raise CaseError(file, f"{key}.contacts[0].axis", "the modal tier's cone turns about the z axis: [0, 0, 1]")
    if contact.damping:
        raise CaseError(file, f"{key}.contacts[0].damping",
                        "contact damping is not available in the modal tier's motor")
    if not contact.exclude_initial_gap:
        raise CaseError(file, f"{key}.contacts[0].exclude_initial_gap",
                        "the modal tier's motor measures the band's gap from the design cone (ANSYS KEYOPT(9) = 1): "
                        "set it to true")
    if len(cfg.bodies) != 1:
        raise CaseError(file, f"{key}.bodies", "the modal tier's motor has one rigid body, the rotor")
    body = cfg.bodies[0]
    if len(body.position_m) != 3 or body.position_m[0] != 0.0 or body.position_m[1] != 0.0:
        raise CaseError(file, f"{key}.bodies[0].position_m", "the rotor's reference point lies on the z axis")
    if body.fixed or (body.free_axes or [True] * 3) != [False, False, True]:
        raise CaseError(file, f"{key}.bodies[0].free_axes", "the rotor translates along z only: [false, false, true]")
    if body.seat_on != contact.name:
        raise CaseError(file, f"{key}.bodies[0].seat_on",
                        "the modal tier's motor starts the rotor seated on the highest crest: "
                        f"set it to {contact.name!r}")
    if not body.mass_kg > 0:
        raise CaseError(file, f"{key}.bodies[0].mass_kg", "the rotor needs a positive mass")
    if len(body.rotations) != 1 or body.rotations[0].axis != "z":
        raise CaseError(file, f"{key}.bodies[0].rotations", "the rotor has one rotation, about z")
    force = body.applied_force_N or [0.0, 0.0, 0.0]
    if force[0] or force[1] or force[2] > 0:
        raise CaseError(file, f"{key}.bodies[0].applied_force_N", "the preload presses the rotor down: [0, 0, -P]")
    if cfg.scheme.kind != "newmark":
        raise CaseError(file, f"{key}.scheme.kind", "the modal tier's motor steps with Newmark (the paper's scheme)")
    if cfg.drive.tip_amplitude_m is not None:
        raise CaseError(file, f"{key}.drive.tip_amplitude_m", "the motor is driven by its electrode voltages")
    if cfg.loads.gravity_m_per_s2 or cfg.loads.fe_force_N:
        raise CaseError(file, f"{key}.loads", "the motor's axial load is the rotor's applied force (preload)")
    if cfg.base_motions:
        raise CaseError(file, f"{key}.base_motions", "not available in the modal tier's motor")
