"""[transient] validation: bad input names the dotted key (exit 2 via CaseError)."""

from __future__ import annotations

import pytest

from app.case.transient import TransientSection
from app.case.validate import from_dict
from app.errors import CaseError
from app.transient.forces import friction_of


def _section(**changes):
    data = {"end_time_s": 1e-3, "output_interval_s": 1e-4,
            "bodies": [{"name": "ball", "position_m": [0.0, -0.004], "mass_kg": 2e-3}],
            "contacts": [{"name": "tip_ball", "kind": "surface", "stiffness": 1e15, "facets": "tip", "body": "ball",
                          "shape": "sphere", "radius_m": 0.004}]}
    data.update(changes)
    return data


def test_valid_section_builds_the_scheme():
    section = from_dict(TransientSection, _section(), "case.toml", "transient")
    assert section.scheme.scheme().alpha_f == pytest.approx(1 / 3)


@pytest.mark.parametrize("changes, key", [
    ({"output_interval_s": 1e-7}, "transient.steps.open_s"),
    ({"contacts": [{"name": "c", "kind": "surface", "stiffness": 0.0, "facets": "tip", "body": "ball",
                    "shape": "sphere", "radius_m": 0.004}]}, "transient.contacts[0].stiffness"),
    ({"contacts": [{"name": "c", "kind": "surface", "stiffness": 1.0, "facets": "tip", "body": "anvil",
                    "shape": "sphere", "radius_m": 0.004}]}, "transient.contacts[0].body"),
    ({"contacts": [{"name": "c", "kind": "point", "stiffness": 1.0, "lower": "ball", "upper": "stem",
                    "direction": [0.0, 1.0]}]}, "transient.contacts[0].upper"),
    ({"bodies": [{"name": "ball", "position_m": [0.0, 0.0]}]}, "transient.bodies[0].mass_kg"),
])
def test_bad_input_names_the_key(changes, key):
    with pytest.raises(CaseError) as err:
        from_dict(TransientSection, _section(**changes), "case.toml", "transient")
    assert err.value.key == key


SURFACE = {"name": "c", "kind": "surface", "stiffness": 1.0, "facets": "tip", "body": "ball", "shape": "sphere",
           "radius_m": 0.004}
POINT = {"name": "p", "kind": "point", "stiffness": 1.0, "lower": "ball", "upper": "ball2", "direction": [0.0, 1.0]}
TWO_BODIES = [{"name": "ball", "position_m": [0.0, -0.004], "mass_kg": 2e-3},
              {"name": "ball2", "position_m": [0.0, -0.008], "mass_kg": 2e-3}]


@pytest.mark.parametrize("contact, key, message", [
    ({**POINT, "radius_m": 0.004}, "transient.contacts[1].radius_m", "not a key of kind 'point'"),
    ({**POINT, "facets": "tip"}, "transient.contacts[1].facets", "not a key of kind 'point'"),
    ({**SURFACE, "name": "s", "lower": "ball"}, "transient.contacts[1].lower", "not a key of kind 'surface'"),
    ({**SURFACE, "name": "s", "contact_offset_m": 0.1}, "transient.contacts[1].contact_offset_m",
     "not a key of kind 'surface'"),
    ({**POINT, "kind": "spring"}, "transient.contacts[1].kind", "must be one of"),
    ({k: v for k, v in POINT.items() if k != "kind"}, "transient.contacts[1].kind", "required key is missing"),
    ({**POINT, "bogus": 1}, "transient.contacts[1].bogus", "unknown key"),
    ({**POINT, "friction": {"mu_dynamic": 0.2, "shear_cap_Pa": 1e6}}, "transient.contacts[1].friction.shear_cap_Pa",
     "unknown key"),
    ({**SURFACE, "name": "s", "friction": {"mu_dynamic": -0.2}}, "transient.contacts[1].friction.mu_dynamic",
     "must be >="),
])
def test_contacts_are_a_tagged_union_on_kind(contact, key, message):
    data = _section(bodies=TWO_BODIES, contacts=[{**SURFACE, "name": "first"}, contact])
    with pytest.raises(CaseError) as err:
        from_dict(TransientSection, data, "case.toml", "transient")
    assert err.value.key == key
    assert message in err.value.message


def test_friction_and_rotations_from_a_case():
    bodies = [{"name": "rotor", "position_m": [0.0, 0.0], "mass_kg": 1.0, "free_axes": [False, True],
               "rotations": [{"axis": "plane", "inertia_kg_m2": 1e-3, "rate_rad_per_s": 10.0}]},
              {"name": "ground", "position_m": [0.0, -1.0], "fixed": True,
               "rotations": [{"axis": "plane", "motion": "constant_rate", "rate_rad_per_s": 3.0}]}]
    contacts = [{**SURFACE, "body": "rotor", "friction": {"mu_dynamic": 0.2, "static_ratio": 1.5,
                                                          "decay_s_per_m": 10.0, "shear_cap_Pa": 1e6}},
                {**POINT, "lower": "ground", "upper": "rotor", "contact_offset_m": 0.01,
                 "friction": {"mu_dynamic": 0.3, "force_cap_N": 5.0}}]
    section = from_dict(TransientSection, _section(bodies=bodies, contacts=contacts), "case.toml", "transient")
    surface, point = section.contacts
    assert type(surface).__name__ == "SurfaceContactSection" and type(point).__name__ == "PointContactSection"
    friction = friction_of(surface.friction)
    assert (friction.mu_dynamic, friction.static_ratio, friction.decay_s_per_m, friction.shear_cap_Pa) == \
        (0.2, 1.5, 10.0, 1e6)
    assert friction_of(point.friction).shear_cap_Pa == 5.0 and point.contact_offset_m == 0.01
    assert section.bodies[0].rotations[0].inertia_kg_m2 == 1e-3


@pytest.mark.parametrize("body, key", [
    ({"name": "r", "position_m": [0.0, 0.0], "mass_kg": 1.0, "rotations": [{"axis": "z", "inertia_kg_m2": 1.0}]},
     "transient.bodies[0].rotations[0].axis"),
    ({"name": "r", "position_m": [0.0, 0.0, 0.0], "mass_kg": 1.0, "rotations": [{"axis": "plane"}]},
     "transient.bodies[0].rotations[0].inertia_kg_m2"),
    ({"name": "r", "position_m": [0.0, 0.0], "mass_kg": 1.0,
      "rotations": [{"axis": "plane", "inertia_kg_m2": 1.0}, {"axis": "plane", "inertia_kg_m2": 1.0}]},
     "transient.bodies[0].rotations[1].axis"),
    ({"name": "r", "position_m": [0.0, 0.0], "fixed": True, "rotations": [{"axis": "plane", "inertia_kg_m2": 1.0}]},
     "transient.bodies[0].rotations[0].motion"),
])
def test_bad_rotations_name_the_key(body, key):
    with pytest.raises(CaseError) as err:
        from_dict(TransientSection, _section(bodies=[body], contacts=[]), "case.toml", "transient")
    assert err.value.key == key
