"""Tiers as a registry (app/case/options.py): each tier's analyses, required and foreign sections are
checked when the case is loaded, before any mesh is built; bad input names the key."""

from __future__ import annotations

import pytest
from conftest import CASES

from app.case.options import TIERS
from app.case.schema import load_case
from app.errors import CaseError


@pytest.mark.parametrize("case, overrides, key", [
    ("usdc-lumped.toml", ['analyses=["transient"]'], "analyses[0]"),
    ("usdc-fe.toml", ['analyses=["lumped"]'], "analyses[0]"),
    ("usdc-lumped.toml", ["transient.end_time_s=1e-3", "transient.output_interval_s=1e-4"], "transient"),
    ("usdc-transducer.toml", ['analyses=["transient"]'], "transient"),
    ("usdc-fe.toml", ['tier="lumped"'], "analyses[0]"),
    ("usdc-fe.toml", ['tier="lumped"', 'analyses=["lumped"]'], "lumped"),
])
def test_tier_checks_name_the_key(case, overrides, key):
    with pytest.raises(CaseError) as err:
        load_case(CASES / case, overrides)
    assert err.value.key == key


def test_default_analyses_come_from_the_registry():
    assert load_case(CASES / "usdc-lumped.toml").analyses == list(TIERS["lumped"].default_analyses)
    for name, tier in TIERS.items():
        assert set(tier.default_analyses) <= set(tier.analyses), name
    assert load_case(CASES / "validation" / "pzt4-disc.toml").tier == "fe"
