"""Reading TOML case files and applying ``--set dotted.key=value`` overrides."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from app.errors import CaseError


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; unreadable or malformed files raise CaseError."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CaseError(str(path), None, f"case file is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise CaseError(str(path), None, f"cannot read case file ({exc.strerror or exc})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(str(path), None, f"invalid TOML: {exc}") from None


def parse_override(text: str) -> tuple[list[str], Any]:
    """``a.b.c=value`` -> (["a", "b", "c"], value); the value is read as a TOML value,
    falling back to a bare string so ``--set mesh.file=bar.msh`` works unquoted."""
    if "=" not in text:
        raise CaseError("--set", text, "expected dotted.key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise CaseError("--set", text, "expected dotted.key=value")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key.split("."), value


_INDEXED = re.compile(r"^(?P<name>[^\[\]]+)\[(?P<index>\d+)\]$")


def _step(node, part: str, path: str, create: bool):
    """The child ``part`` of ``node`` (``name`` or ``name[i]``, an entry of an array of tables),
    created as an empty table if missing and ``create``."""
    match = _INDEXED.match(part)
    name = match["name"] if match else part
    if not isinstance(node, dict):
        raise CaseError("--set", path, "is not a table")
    if match is None:
        if node.get(name) is None and create:
            node[name] = {}
        return node.get(name)
    items, index = node.get(name), int(match["index"])
    if not isinstance(items, list):
        raise CaseError("--set", path, f"{name!r} is not an array of tables")
    if index >= len(items):
        raise CaseError("--set", path, f"{name!r} has {len(items)} entries (indices from 0)")
    return items[index]


def apply_overrides(data: dict[str, Any], overrides: list[str] | None) -> dict[str, Any]:
    """Return a copy of ``data`` with each ``dotted.key=value`` set (tables created as needed);
    ``name[i]`` selects entry i of an array of tables (``transient.bodies[0].mass_kg=0.1``)."""
    import copy

    out = copy.deepcopy(data)
    for text in overrides or []:
        parts, value = parse_override(text)
        node = out
        for i, part in enumerate(parts[:-1]):
            path = ".".join(parts[: i + 1])
            node = _step(node, part, path, create=True)
            if not isinstance(node, dict):
                raise CaseError("--set", path, "is not a table")
        last = parts[-1]
        match = _INDEXED.match(last)
        if match:
            _step(node, last, ".".join(parts), create=False)     # checks the array and the index
            node[match["name"]][int(match["index"])] = value
        else:
            node[last] = value
    return out
