"""Reading TOML case files and applying ``--set dotted.key=value`` overrides."""

from __future__ import annotations

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


def apply_overrides(data: dict[str, Any], overrides: list[str] | None) -> dict[str, Any]:
    """Return a copy of ``data`` with each ``dotted.key=value`` set (tables created as needed)."""
    import copy

    out = copy.deepcopy(data)
    for text in overrides or []:
        parts, value = parse_override(text)
        node = out
        for i, part in enumerate(parts[:-1]):
            nxt = node.get(part)
            if nxt is None:
                nxt = node[part] = {}
            if not isinstance(nxt, dict):
                raise CaseError("--set", ".".join(parts[: i + 1]), "is not a table")
            node = nxt
        node[parts[-1]] = value
    return out
