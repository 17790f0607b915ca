"""``piezodyn cases``: the case files shipped with piezodyn, with their titles."""

from __future__ import annotations

import tomllib
from pathlib import Path

CASES_DIR = Path(__file__).resolve().parents[1] / "cases"


def _description(path: Path, data: dict) -> str:
    """The case's title, else the first line of its leading comment."""
    if data.get("title"):
        return str(data["title"])
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
        if line.strip():
            break
    return ""


def shipped_cases(root: Path = CASES_DIR) -> list[dict]:
    """[{path, tier, analyses, title}] for every case file under ``root``, sorted by path."""
    rows = []
    for path in sorted(root.rglob("*.toml")):
        with open(path, "rb") as f:
            data = tomllib.load(f)
        tier = data.get("tier", "fe")
        analyses = data.get("analyses") or (["lumped"] if tier == "lumped" else ["modal"])
        rows.append({"path": path, "tier": tier, "analyses": list(analyses), "title": _description(path, data)})
    return rows


def shown_path(path: Path, cwd: Path | None = None) -> str:
    """``path`` as a user can pass it from ``cwd`` (default: the working directory): relative when it lies
    below it (a source checkout), else absolute (the Docker image runs in /work, the cases are installed under
    /opt/piezodyn/cases)."""
    cwd = Path.cwd() if cwd is None else Path(cwd)
    try:
        return str(path.resolve().relative_to(cwd.resolve()))
    except ValueError:
        return str(path.resolve())


def format_cases(root: Path = CASES_DIR, cwd: Path | None = None) -> str:
    """The case table; each path opens from ``cwd`` (default: the working directory)."""
    rows = shipped_cases(root)
    names = [shown_path(r["path"], cwd) for r in rows]
    kinds = [r['tier'] if r['analyses'] == [r['tier']] else f"{r['tier']}: {', '.join(r['analyses'])}" for r in rows]
    w1, w2 = max(map(len, names), default=4), max(map(len, kinds), default=4)
    lines = [f"{len(rows)} case files in {root}:"]
    lines += [f"  {n:<{w1}}  {k:<{w2}}  {r['title']}" for n, k, r in zip(names, kinds, rows)]
    lines.append("run one with: piezodyn run <path> [--out DIR]; check one with: piezodyn validate <path>")
    return "\n".join(lines)
