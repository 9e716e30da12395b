"""The package's shape: stages as subpackages, no import cycles, small modules, a thin CLI.

These checks read the source (``ast``), so they see imports inside functions too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "polyrob"
#: A smell guard, not a target: past it a module surely holds more than one topic.  Modules are split
#: where their topics part, never at a count (a cap just above the largest module had them stop at 400).
MAX_LINES = 600


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """polyrob modules that ``name`` imports (package ``__init__`` re-exports excluded)."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        for t in targets:
            if t in known and t != name:
                found.add(t)
    return found


def _graph():
    mods = _modules()
    known = set(mods)
    return {m: _imports(m, p, known) for m, p in mods.items()}


def test_no_import_cycles_between_modules():
    graph = _graph()
    # A package's __init__ re-exports its children; an edge child -> package is a
    # use of that facade, not a cycle in the data flow, so package nodes are skipped.
    packages = {m for m, p in _modules().items() if p.name == "__init__.py"}
    edges = {m: {t for t in ts if t not in packages} for m, ts in graph.items() if m not in packages}
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        for nxt in edges.get(node, ()):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt] if nxt in stack else [node, nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in edges:
        if node not in state:
            visit(node, [node])
    assert not cycles, f"import cycles: {cycles}"


def test_no_module_above_the_line_limit():
    too_long = {m: n for m, p in _modules().items() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not too_long, f"modules above {MAX_LINES} lines: {too_long}"


def test_no_private_name_imported_across_modules():
    offenders = []
    for name, path in _modules().items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("polyrob"):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        offenders.append(f"{name}: from {node.module} import {alias.name}")
    assert not offenders, "private names imported across modules:\n" + "\n".join(offenders)


def test_stages_are_subpackages():
    for stage in ["model", "bounds", "plant", "analysis", "synthesis", "io"]:
        assert (PACKAGE / stage / "__init__.py").is_file(), stage


@pytest.mark.parametrize("numeric", ["numpy", "scipy", "control", "slycot", "cvxpy", "pinocchio"])
def test_cli_holds_no_numerical_code(numeric):
    """The CLI parses, calls the library, prints: it imports no numerical package itself."""
    cli = [p for m, p in _modules().items() if m == "polyrob.cli" or m.startswith("polyrob.cli.")]
    assert cli
    for path in cli:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            else:
                continue
            assert not any(n == numeric or n.startswith(numeric + ".") for n in names), f"{path.name} imports {numeric}"


#: Most modules in one subpackage (``__init__`` not counted): above it, a topic wants a subpackage of its own.
MAX_MODULES = 12


def test_no_subpackage_holds_more_than_a_dozen_modules():
    crowded = {}
    for package in PACKAGE.rglob("__init__.py"):
        modules = [m for m in package.parent.glob("*.py") if m.name != "__init__.py"]
        if len(modules) > MAX_MODULES:
            crowded[str(package.parent.relative_to(PACKAGE.parent))] = len(modules)
    assert not crowded, f"subpackages with more than {MAX_MODULES} modules: {crowded}"
