"""Generates docs/cases.md from the schema dataclasses (``python -m app.case.docgen > docs/cases.md``);
a test keeps the committed file in sync."""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Literal

from app.case import schema
from app.case.validate import _type_name
from app.materials import Material, PiezoDForm, PiezoEForm

INTRO = """# Case files

A case is a TOML file validated into typed objects before any mesh or solver exists. Unknown keys,
wrong types and out-of-range values stop the run with one line naming the file and the dotted key
(exit status 2). Any key can be overridden on the command line: `--set modal.n_modes=12`,
`--set 'analyses=["modal"]'`, `--set materials.steel.young_Pa=2.1e11` (values are TOML; bare words
are strings).

This page is generated from the schema (`python -m app.case.docgen > docs/cases.md`).
"""


def _default(f) -> str:
    if f.default is not dataclasses.MISSING:
        return "`" + repr(f.default) + "`"
    if f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
        return "defaults" if dataclasses.is_dataclass(value) else "`" + repr(value) + "`"
    return "required"


def table(cls, title: str) -> list[str]:
    hints = typing.get_type_hints(cls)
    lines = [f"## {title}", "", "| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        if f.name == "source":
            continue
        meta = f.metadata or {}
        bounds = ", ".join(f"{op} {meta[k]}" for k, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
                           if meta.get(k) is not None)
        doc = meta.get("doc", "") + (f" ({bounds})" if bounds else "")
        type_name = _type_name(hints[f.name]).replace("|", "or")
        lines.append(f"| `{f.name}` | {type_name} | {_default(f)} | {meta.get('unit', '')} | {doc} |")
    return lines + [""]


def _dataclass_members(tp) -> tuple[bool, list]:
    """(is a list, the dataclasses) a field of type ``tp`` holds: ``X``, ``X | None``, ``list[X]`` or a
    list of a tagged union (one dataclass per ``kind``)."""
    is_list = typing.get_origin(tp) is list
    args = typing.get_args(tp) if is_list else (tp,)
    members = []
    for arg in args:
        for option in (typing.get_args(arg) if typing.get_origin(arg) in (typing.Union, types.UnionType) else (arg,)):
            if dataclasses.is_dataclass(option):
                members.append(option)
    return is_list, members


def tables_below(cls, prefix: str, seen: set, context: str = "") -> list[str]:
    """Tables of the sub-sections of ``cls`` (dataclass fields, lists of them, tagged unions), depth
    first, titled with their dotted TOML paths (every field a class serves); each class once.
    ``context``: the tagged-union kind the parent belongs to, repeated in the titles below it."""
    hints = typing.get_type_hints(cls)
    uses: dict = {}                                  # member class -> [(title, kind tag)]
    for f in dataclasses.fields(cls):
        is_list, members = _dataclass_members(hints[f.name])
        path = f"{prefix}.{f.name}"
        for member in members:
            kind = typing.get_type_hints(member).get("kind")
            tag = typing.get_args(kind) if typing.get_origin(kind) is Literal else ()
            union_tag = tag[0] if len(members) > 1 and len(tag) == 1 else None
            uses.setdefault(member, []).append((f"[[{path}]]" if is_list else f"[{path}]", path, union_tag))
    parts = []
    for member, where in uses.items():
        if member in seen:
            continue
        seen.add(member)
        title = ", ".join(t for t, _, _ in where)
        tag = where[0][2]
        suffix = f' with kind = "{tag}"' if tag else context
        parts.append("\n".join(table(member, title + suffix)))
        parts += tables_below(member, where[0][1], seen, f' (of kind = "{tag}")' if tag else context)
    return parts


def render() -> str:
    from geometry.builders import BUILDERS

    parts = [INTRO]
    sections = [
        (schema.Case, "Top level"),
        (schema.GeometrySection, "[geometry]"),
        (Material, "[materials.NAME]"),
        (PiezoEForm, "[materials.NAME.piezo_e] (stress-charge, 6mm, poled along material axis 3)"),
        (PiezoDForm, "[materials.NAME.piezo_d] (strain-charge datasheet form, converted on input)"),
        (schema.Region, "[[regions]]"),
        (schema.Electrode, "[electrodes.NAME]"),
        (schema.Support, "[[supports]]"),
        (schema.Point, "[points.NAME]"),
        (schema.DampingSection, "[damping]"),
        (schema.ModalSection, "[modal]"),
        (schema.HarmonicSection, "[harmonic]"),
        (schema.TargetAmplitude, "[harmonic.target]"),
        (schema.CircuitSection, "[circuit]"),
        (schema.ReductionSection, "[reduction]"),
        (schema.OutputSection, "[output]"),
    ]
    for name, (params_cls, _) in BUILDERS.items():
        sections.append((params_cls, f"[geometry.parameters] for builder = \"{name}\""))
    for cls_path, title in (("app.case.lumped:LumpedSection", "[lumped]"),
                            ("app.case.lumped:FrictionDriveSection", "[lumped] with model = \"friction_drive\""),
                            ("app.case.transient:TransientSection", "[transient]")):
        module, _, attr = cls_path.partition(":")
        try:
            cls = getattr(__import__(module, fromlist=[attr]), attr)
        except (ImportError, AttributeError):
            continue
        sections.append((cls, title))
    seen = {cls for cls, _ in sections}
    for cls, title in sections:
        parts.append("\n".join(table(cls, title)))
        if title.startswith("[") and not title.startswith("[["):
            prefix = title[1:title.index("]")]
            context = title[title.index("]") + 1:]          # ' with model = "..."': the sub-tables say it too
            parts += tables_below(cls, prefix, seen, f" (of{context[5:]})" if context.startswith(" with ") else "")
    library = ", ".join(f"`{n}`" for n in __import__("app.materials", fromlist=["LIBRARY"]).LIBRARY)
    parts.append(f"## Material library\n\n`library = ...` copies one of: {library}; keys given next to it "
                 "override the entry. See docs/physics.md for the data and its sources.\n")
    return "\n".join(parts)


if __name__ == "__main__":
    print(render(), end="")
