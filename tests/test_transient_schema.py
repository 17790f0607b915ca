"""[transient] validation: bad input names the dotted key (exit 2 via CaseError)."""

from __future__ import annotations

import pytest

from app.case.validate import from_dict
from app.errors import CaseError
from app.transient.schema import TransientSection


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
