"""The house rules of issue 32 as tests, read from the code with ``ast`` (the module walker of ``test_layers``).

- private names stay home: no ``_name`` imported from a module of another package; inside a package, ``_names``
  come only from that package's ``common.py`` (the one module that holds its shared internals); the same for
  ``module._name`` through an imported module;
- no function or method outside ``hpe_cli/cli/`` longer than ``MAX_LINES`` lines (``def`` line to last line);
- no function in ``hpe_cli/pipelines/`` with more than ``MAX_PARAMS`` parameters (``self``/``cls`` excluded;
  ``*args``/``**kwargs`` count one each);
- ``get_system(`` in ``hpe_cli/pipelines/`` only where a user-given name enters (``GET_SYSTEM_ALLOWED``, each
  with its reason): pipelines take a ``LabelSource`` or a ``RotationSystem``, never a name to resolve again;
- function-level imports only of heavy modules (``LAZY_OK``: each costs 0.15 s or more to import, measured in
  docs/performance.md), inside ``try`` (an optional dependency probed), or marked ``# lazy: REASON`` on the
  import line (kept off the start-up path of ``hpe --help`` and a small ``hpe convert``); anything in
  ``hpe_cli/cli/`` (the click modules load pipelines lazily so that ``hpe --help`` starts fast).

Each rule has a ``KNOWN_*`` set of the violations of the day the rule was written (one per line, keyed by
``path::qualname`` so that unrelated edits do not move them). A rule fails on any violation not in its set,
and on any entry of its set that no longer occurs, so the sets only shrink; they are to end empty.
Moving or renaming a module or function moves its entries: ``python tests/project/test_house.py`` prints the
violations of today in the format of the sets, to copy from; ``--update`` rewrites the sets in this file (review
the diff: an added line is a new violation).
"""

from __future__ import annotations

import ast
import json
import sys
from functools import cache
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_layers import MODULES, ROOT, _is_package  # noqa: E402

MAX_LINES = 100
MAX_PARAMS = 8
#: top-level modules a function may import lazily anywhere: the optional extras, and the dependencies that each
#: take 0.15 s or more to import (scipy.io 0.26 s, pandas 0.39 s, cv2 0.16 s; docs/performance.md, start-up)
LAZY_OK = {"torch", "torchvision", "dask", "distributed", "matplotlib", "scipy", "pandas", "cv2", "duckdb", "tqdm"}
#: the comment that keeps a function-level import lazy, with its reason
LAZY_MARK = "# lazy:"


@cache
def _tree(name: str) -> ast.Module:
    path = MODULES[name]
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _rel(name: str) -> str:
    """``hpe_cli/x/y.py`` of a module name."""
    return MODULES[name].relative_to(ROOT.parent).as_posix()


def _package(name: str) -> str:
    """The package a module belongs to (a package's ``__init__`` belongs to the package itself)."""
    return name if _is_package(name) else name.rpartition(".")[0]


def _target(name: str, node: ast.ImportFrom) -> str:
    """The absolute module name of ``from X import ...`` in module ``name`` (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    base = name.split(".") if _is_package(name) else name.split(".")[:-1]
    return ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _walk(tree: ast.AST):
    """``(qualname, node, function)`` of every node below ``tree``: ``qualname`` is the node's own for a function
    or class, else that of the innermost enclosing function (``<module>`` outside any); ``function`` is the
    qualname of the innermost function enclosing the node (None at module or class level)."""

    def visit(node, prefix, func):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                qual = prefix + child.name
                yield qual, child, func
                yield from visit(child, qual + ".", func if isinstance(child, ast.ClassDef) else qual)
            else:
                yield func or "<module>", child, func
                yield from visit(child, prefix, func)

    yield from visit(tree, "", None)


def _functions(name: str):
    """``(qualname, node)`` of every function and method of a module (nested ones too)."""
    for qual, node, _ in _walk(_tree(name)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield qual, node


def _in(name: str, *packages: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


# ---------------------------------------------------------------------------------------------------------------
# the violations of today, per rule


def private_imports() -> set:
    """``path::imported.module._name`` for every private name imported against the rule."""
    out = set()
    for name in MODULES:
        own = _package(name)
        for node in ast.walk(_tree(name)):
            if isinstance(node, ast.ImportFrom):
                target = _target(name, node)
                if not _in(target, "hpe_cli"):
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    module = sub if sub in MODULES else target
                    if not _private(alias.name) and module == target:
                        continue
                    if module != target and not _private(alias.name):
                        continue  # a public submodule
                    if module == target:  # a private name of module ``target``
                        home = _package(target)
                        ok = home == own and (target == name or target.rpartition(".")[2] == "common")
                    else:  # a private submodule ``sub`` of package ``target``
                        ok = target == own
                    if not ok:
                        out.add(f"{_rel(name)}::{target}.{alias.name}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    parts = alias.name.split(".")
                    if parts[0] == "hpe_cli" and any(_private(p) for p in parts):
                        out.add(f"{_rel(name)}::{alias.name}")
        out |= _private_attributes(name, own)
    return out


def _private_attributes(name: str, own: str) -> set:
    """``module._name`` reached through a module bound by an import (``from . import x``; ``x._name``)."""
    tree, bound, out = _tree(name), {}, set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _target(name, node)
            for alias in node.names:
                if f"{target}.{alias.name}" in MODULES:
                    bound[alias.asname or alias.name] = f"{target}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname and alias.name in MODULES:
                    bound[alias.asname] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and _private(node.attr):
            module = bound.get(node.value.id)
            if module and not (_package(module) == own and module.rpartition(".")[2] == "common"):
                out.add(f"{_rel(name)}::{module}.{node.attr}")
    return out


def long_functions() -> set:
    """``path::qualname`` of every function over ``MAX_LINES`` lines outside ``hpe_cli/cli/``."""
    return {
        f"{_rel(name)}::{qual}"
        for name in MODULES
        if not _in(name, "hpe_cli.cli")
        for qual, node in _functions(name)
        if node.end_lineno - node.lineno + 1 > MAX_LINES
    }


def _n_params(qual: str, node) -> int:
    a = node.args
    names = [p.arg for p in a.posonlyargs + a.args]
    is_method = "." in qual and not any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in node.decorator_list)
    if is_method and names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def many_parameters() -> set:
    """``path::qualname`` of every function in ``hpe_cli/pipelines/`` with over ``MAX_PARAMS`` parameters."""
    return {
        f"{_rel(name)}::{qual}"
        for name in MODULES
        if _in(name, "hpe_cli.pipelines")
        for qual, node in _functions(name)
        if _n_params(qual, node) > MAX_PARAMS
    }


def get_system_calls() -> set:
    """``path::qualname: get_system(argument)`` of every ``get_system(`` call in ``hpe_cli/pipelines/``."""
    out = set()
    for name in MODULES:
        if not _in(name, "hpe_cli.pipelines"):
            continue
        for qual, node, _ in _walk(_tree(name)):
            if isinstance(node, ast.Call):
                f = node.func
                called = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
                if called == "get_system":
                    args = ", ".join(ast.unparse(a) for a in node.args)
                    out.add(f"{_rel(name)}::{qual}: get_system({args})")
    return out


def _guarded_imports(tree) -> set:
    """ids of the import statements inside a ``try`` block (optional dependencies probed)."""
    return {
        id(node)
        for t in ast.walk(tree)
        if isinstance(t, ast.Try)
        for stmt in t.body
        for node in ast.walk(stmt)
        if isinstance(node, (ast.Import, ast.ImportFrom))
    }


def lazy_imports() -> set:
    """``path::qualname: module`` of every function-level import outside ``hpe_cli/cli/`` that is not of a
    ``LAZY_OK`` module, not inside ``try`` and not marked ``# lazy: REASON``."""
    out = set()
    for name in MODULES:
        if _in(name, "hpe_cli.cli"):
            continue
        tree = _tree(name)
        guarded = _guarded_imports(tree)
        lines = MODULES[name].read_text(encoding="utf-8").splitlines()
        for qual, node, func in _walk(tree):
            if func is None or not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if id(node) in guarded or LAZY_MARK in lines[node.end_lineno - 1]:
                continue
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                targets = [_target(name, node)]
            for target in targets:
                if target.split(".")[0] not in LAZY_OK:
                    out.add(f"{_rel(name)}::{qual}: {target}")
    return out


# ---------------------------------------------------------------------------------------------------------------
# the rules

#: ``get_system(`` calls of ``hpe_cli/pipelines/`` where a user-given name enters -> why
GET_SYSTEM_ALLOWED = {
    "hpe_cli/pipelines/relabel/options.py::_label_system: get_system(system)": "relabel-panoptic/-agora --system",
    "hpe_cli/pipelines/biwi.py::BiwiOptions.__post_init__: get_system(self.system)": "biwi --system",
    "hpe_cli/pipelines/export/job.py::_layout_and_system: get_system(layout.system)": (
        "the system the --layout's trainer expects (the layout names it)"
    ),
    "hpe_cli/pipelines/draw/errors.py::_load: get_system(system)": (
        "draw_worst/render_worst system= (a library caller's name, or a DataFrame's attrs['hpe:system'])"
    ),
    "hpe_cli/pipelines/export/job.py::_layout_and_system: get_system(opts.system)": (
        "ExportOptions(system=...) built by library code may hold a name (the CLI passes a RotationSystem)"
    ),
    "hpe_cli/pipelines/relabel/plan.py::Config.__post_init__: get_system(self.system)": (
        "relabel Config(system=...) built by library code holds a name; resolved once, before the worker processes"
    ),
    "hpe_cli/pipelines/view/job.py::also_angles: get_system(s)": "view --also-in (names of other systems)",
}

KNOWN_PRIVATE_IMPORTS: set = set()
KNOWN_LONG_FUNCTIONS: set = set()
KNOWN_MANY_PARAMETERS: set = set()
KNOWN_GET_SYSTEM: set = set()
KNOWN_LAZY_IMPORTS: set = set()

RULES = {
    "private names imported across modules (from another package, or not from the package's common.py)": (
        private_imports,
        KNOWN_PRIVATE_IMPORTS,
    ),
    f"functions over {MAX_LINES} lines outside hpe_cli/cli/": (long_functions, KNOWN_LONG_FUNCTIONS),
    f"pipeline functions with over {MAX_PARAMS} parameters": (many_parameters, KNOWN_MANY_PARAMETERS),
    "get_system( in hpe_cli/pipelines/ where no user-given name enters (take a LabelSource or RotationSystem)": (
        lambda: get_system_calls() - set(GET_SYSTEM_ALLOWED),
        KNOWN_GET_SYSTEM,
    ),
    f"function-level imports outside hpe_cli/cli/ (only {', '.join(sorted(LAZY_OK))} may be lazy)": (
        lazy_imports,
        KNOWN_LAZY_IMPORTS,
    ),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_house_rule(rule):
    found, known = RULES[rule][0](), RULES[rule][1]
    new, gone = sorted(found - known), sorted(known - found)
    msg = []
    if new:
        msg.append(f"{rule}: {len(new)} new (fix them; a moved function moves its entry in KNOWN):")
        msg += [f"    {json.dumps(v)}," for v in new]
    if gone:
        msg.append(f"{rule}: {len(gone)} KNOWN no longer found (fixed or moved: delete these lines):")
        msg += [f"    {json.dumps(v)}," for v in gone]
    assert not msg, "\n".join(msg)


def test_allowed_get_system_calls_exist():
    gone = sorted(set(GET_SYSTEM_ALLOWED) - get_system_calls())
    assert not gone, "GET_SYSTEM_ALLOWED entries no longer found (delete or update):\n" + "\n".join(gone)


#: test files that may start hpe themselves -> why (everything else calls ``conftest.hpe``/``hpe_process``/``hpe_popen``)
OWN_RUNNER_OK = {
    "tests/conftest.py": "the one runner",
    "tests/docs/doc_examples.py": "a script (--update) that runs the docs' shell lines outside pytest",
    "tests/project/test_house.py": "names the patterns it looks for",
    "tests/project/test_registries.py": "a fresh interpreter that runs --help and lists the modules it loaded",
}


def test_one_cli_runner_for_the_tests():
    tests = ROOT.parent / "tests"
    bad = []
    for path in sorted(tests.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).as_posix()
        text = path.read_text(encoding="utf-8")
        if rel not in OWN_RUNNER_OK and ("CliRunner(" in text or '"-m", "hpe_cli"' in text or '"hpe_cli",\n' in text):
            bad.append(rel)
    assert not bad, "run the CLI with conftest.hpe / hpe_process / hpe_popen, not a runner of its own:\n" + "\n".join(
        bad
    )


def test_the_walker_sees_the_code():
    # guards against a walker that silently finds nothing
    assert "hpe_cli/pipelines/export/job.py::_layout_and_system" in {
        f"{_rel(n)}::{q}" for n in MODULES if _in(n, "hpe_cli.pipelines.export") for q, _ in _functions(n)
    }
    assert any(q.startswith("hpe_cli/pipelines/biwi.py::BiwiOptions.__post_init__: ") for q in get_system_calls())


def _update_known() -> None:
    """Rewrite the ``KNOWN_*`` sets of this file with today's violations (after a merge that moved functions:
    review the diff, an added line is a new violation)."""
    import re

    path = Path(__file__)
    text = path.read_text(encoding="utf-8")
    for find, known in RULES.values():
        name = next(k for k, v in globals().items() if k.startswith("KNOWN_") and v is known)
        body = "".join(f"    {json.dumps(v)},\n" for v in sorted(find()))
        new = f"{name} = {{\n{body}}}" if body else f"{name}: set = set()"
        # a set over several lines, the one line ruff makes of a short one, or an empty set
        pattern = rf"(?ms)^{name}(: set)? = (\{{\n.*?^\}}|\{{[^\n]*\}}|set\(\))"
        text = re.sub(pattern, lambda _: new, text, count=1)
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":  # print today's violations in the format of the KNOWN sets; --update rewrites them
    if sys.argv[1:] == ["--update"]:
        _update_known()
        sys.exit(0)
    for rule, (find, _) in RULES.items():
        print(f"# {rule}")
        for v in sorted(find()):
            print(f"    {json.dumps(v)},")
