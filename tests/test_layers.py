"""The layers of docs/adding-a-scene.md and DESIGN section 3, as a test: the import graph of app/, forms/ and
geometry/ (every ``import`` and ``from ... import``, at module level or inside functions, relative ones
resolved, and the module names given as strings to ``import_module`` or in ``"module:name"`` registries) has
no cycle, and nothing below the top layer (the runner, the CLI, the sweep, the report) and the scenes imports
them: the engines, the FE model and analyses, the case layer, forms and geometry point down only."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "forms", "geometry")
TOP = ("app.runner", "app.cli", "app.sweep", "app.report", "app.scenes")
LOWER = ("app.transient", "app.reduced", "app.lumped", "app.fe", "app.case", "app.contact", "app.loop", "forms",
         "geometry")
MODULE_STRING = re.compile(r"^((?:app|forms|geometry)(?:\.[A-Za-z_][A-Za-z0-9_]*)+)(?::[A-Za-z_]\w*)?$")


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _resolve(name: str, modules: dict) -> str | None:
    """The longest prefix of a dotted name that is one of our modules."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in modules:
            return candidate
    return None


def import_graph() -> dict[str, set[str]]:
    modules = _modules()
    graph = {m: set() for m in modules}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                match = MODULE_STRING.match(node.value)
                if match:
                    names = [match.group(1)]
            for name in names:
                target = _resolve(name, modules)
                if target is not None and target != module:
                    graph[module].add(target)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    import sys

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _within(module: str, prefixes) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def test_the_import_graph_has_no_cycle():
    cycles = _cycles(import_graph())
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_nothing_below_imports_the_top_layer_or_the_scenes():
    upward = sorted(f"{m} -> {t}" for m, targets in import_graph().items() if _within(m, LOWER)
                    for t in targets if _within(t, TOP))
    assert not upward, "imports into the runner, CLI, sweep, report or scenes: " + ", ".join(upward)


def test_the_graph_sees_imports_inside_functions_and_module_strings():
    """The checks above can fail: the graph holds a function-level import and a registry string we know of."""
    graph = import_graph()
    assert "app.transient.engine" in graph["app.runner"]          # the ENGINES registry string
    assert "app.scenes.percussion_drill" in graph["app.scenes"]   # the shipped scenes, by name
    assert "app.fe.model" in graph["app.reduced.model"]           # imported inside a function
