"""The package's layers as a contract, read from the code's own imports (``ast``; function-level imports too).

Every ``hpe_cli`` module is parsed, relative imports are resolved, and ``from P import name``
counts as importing ``P.name`` when that is a module (else ``P``). The rules (no exceptions):

- each layer imports only the layers listed for it in ``MAY_IMPORT`` (``errors`` and the
  ``data`` folder are the floor, importable by all);
- only ``cli`` imports ``click``; nothing outside ``torch`` imports ``hpe_cli.torch``;
- no import cycles between modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "hpe_cli"

FLOOR = {"errors", "data", "registry", "native"}
#: layer -> the hpe_cli layers it may import (besides itself and FLOOR); "api" is hpe_cli/__init__.py and api.py
MAY_IMPORT = {
    "rotation": set(),
    "geometry": {"rotation"},
    "metrics": {"rotation"},
    "datasets": {"rotation", "geometry", "metrics"},
    "io": {"rotation", "geometry", "metrics", "datasets"},
    "report": {"rotation", "geometry", "metrics", "datasets", "io"},
    "pipelines": {"rotation", "geometry", "metrics", "datasets", "io", "report"},
    "api": {"rotation", "geometry", "metrics", "datasets", "io", "report", "pipelines"},
    "cli": {"rotation", "geometry", "metrics", "datasets", "io", "report", "pipelines", "api"},
    "torch": {"rotation", "geometry", "metrics", "datasets", "io", "report", "pipelines", "api"},
}
ONLY_IN = {"click": {"cli"}}  # third-party module -> the layers allowed to import it


def _modules() -> dict:
    """``{"hpe_cli.x.y": path}`` of every module (a package is its ``__init__.py``)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES.get(name, Path()).name == "__init__.py"


def _imports(name: str, path: Path):
    """``(line, imported module name)`` of every import in the file, resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    base = name.split(".") if _is_package(name) else name.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = base[: len(base) - node.level + 1]
                target = ".".join(pkg + ([node.module] if node.module else []))
            else:
                target = node.module
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                yield node.lineno, sub if sub in MODULES else target


def _layer(module: str) -> str | None:
    """The layer of an ``hpe_cli`` module name (None: not hpe_cli)."""
    parts = module.split(".")
    if parts[0] != "hpe_cli":
        return None
    if len(parts) == 1 or parts[1] in ("api", "api_arrays", "__main__"):
        return "api" if len(parts) == 1 or parts[1] in ("api", "api_arrays") else "cli"
    return parts[1]


GRAPH = {name: sorted({(line, target) for line, target in _imports(name, path)}) for name, path in MODULES.items()}


def _where(name, line):
    return f"{MODULES[name].relative_to(ROOT.parent)}:{line}"


def test_every_layer_imports_only_the_layers_below_it():
    bad = []
    for name, edges in GRAPH.items():
        layer = _layer(name)
        allowed = MAY_IMPORT.get(layer, set()) | FLOOR | {layer}
        for line, target in edges:
            other = _layer(target)
            if other is not None and other not in allowed:
                bad.append(f"{_where(name, line)}: {layer} imports {target} ({other})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", sorted(ONLY_IN))
def test_third_party_packages_stay_in_their_layer(package):
    bad = [
        f"{_where(name, line)}: {target}"
        for name, edges in GRAPH.items()
        for line, target in edges
        if target.split(".")[0] == package and _layer(name) not in ONLY_IN[package]
    ]
    assert not bad, f"{package} imported outside {', '.join(sorted(ONLY_IN[package]))}:\n" + "\n".join(bad)


def test_torch_is_imported_by_nothing_else():
    bad = [
        f"{_where(name, line)}: {target}"
        for name, edges in GRAPH.items()
        for line, target in edges
        if _layer(target) == "torch" and _layer(name) != "torch"
    ]
    assert not bad, "hpe_cli.torch imported outside it:\n" + "\n".join(bad)


def test_no_import_cycles_between_modules():
    edges = {name: {t for _, t in GRAPH[name] if t in MODULES and t != name} for name in MODULES}
    # a package's __init__ importing its own submodules is how packages are built: not a cycle by itself,
    # but a submodule importing back through its package __init__ is one
    index, low, stack, on, cycles, counter = {}, {}, [], set(), [], [0]

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    import sys

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10_000))
    try:
        for v in sorted(edges):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_the_rules_cover_every_layer():
    layers = {_layer(name) for name in MODULES}
    assert layers - FLOOR <= set(MAY_IMPORT), f"layers without a rule: {sorted(layers - FLOOR - set(MAY_IMPORT))}"
