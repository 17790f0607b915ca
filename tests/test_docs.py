"""Documentation that is generated must match the code."""

from conftest import ROOT


def test_case_schema_doc_is_current():
    from app.case.docgen import render

    assert (ROOT / "docs" / "cases.md").read_text() == render(), "run: python -m app.case.docgen > docs/cases.md"
