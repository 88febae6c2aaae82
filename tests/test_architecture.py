"""The house rules of docs/architecture.md, checked on the source: imports only go down the
layer table (imports inside functions included), no import cycle between modules or
packages, and commands/ modules stay thin."""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "parknss"
DOC = ROOT / "docs" / "architecture.md"
COMMAND_MAX_LINES = 150


def layer_table() -> dict[str, int]:
    """unit (top-level module or package of parknss) -> layer, from the doc's table."""
    rows = re.findall(r"^\|\s*L(\d+)\s*\|([^|]+)\|", DOC.read_text(), flags=re.MULTILINE)
    table: dict[str, int] = {}
    for layer, units in rows:
        for unit in re.findall(r"`([a-z_]+)`", units):
            table[unit] = int(layer)
    return table


def module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def unit_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def imports(path: Path) -> list[tuple[str, int]]:
    """(imported parknss module, line) of every import in the file, function bodies too."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg = module_name(path).split(".")
    if path.name != "__init__.py":
        pkg = pkg[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.startswith("parknss")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import
                base = pkg[: len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("parknss"):
                # `from parknss.x import y` may import the module parknss.x.y
                for a in node.names:
                    full = f"{mod}.{a.name}"
                    out.append((full if (SRC.parent / full.replace(".", "/")).exists()
                                or (SRC.parent / (full.replace(".", "/") + ".py")).exists()
                                else mod, node.lineno))
    return out


def sources() -> list[Path]:
    return sorted(SRC.rglob("*.py"))


def test_every_unit_has_a_layer():
    table = layer_table()
    units = {unit_of(module_name(p)) for p in sources()} - {"__init__", "__main__"}
    missing = sorted(units - set(table))
    assert not missing, f"units without a layer in docs/architecture.md: {missing}"


def test_imports_only_go_down():
    table = layer_table()
    bad = []
    for p in sources():
        here = unit_of(module_name(p))
        if here not in table:
            continue
        for mod, line in imports(p):
            there = unit_of(mod)
            if there in table and table[there] > table[here]:
                bad.append(f"{p.relative_to(ROOT)}:{line}: {here} (L{table[here]}) imports "
                           f"{mod} (L{table[there]})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return [*stack[stack.index(m) :], m]
            if m not in state and (found := visit(m)):
                return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (found := visit(n)):
            return found
    return None


def test_no_import_cycle_between_modules_or_packages():
    modules: dict[str, set[str]] = defaultdict(set)
    packages: dict[str, set[str]] = defaultdict(set)
    known = {module_name(p) for p in sources()}
    for p in sources():
        here = module_name(p)
        for mod, _ in imports(p):
            target = mod
            while target not in known and "." in target:
                target = target.rsplit(".", 1)[0]
            if target != here and target in known:
                modules[here].add(target)
            a, b = unit_of(here), unit_of(target)
            if a != b:
                packages[a].add(b)
    assert _cycle(packages) is None, f"package cycle: {' -> '.join(_cycle(packages) or [])}"
    # a package's __init__ re-exporting its own modules is not a cycle of behaviour
    graph = {m: {t for t in ts if not (m.endswith("__init__") or t == m.rsplit(".", 1)[0])}
             for m, ts in modules.items()}
    assert _cycle(graph) is None, f"module cycle: {' -> '.join(_cycle(graph) or [])}"


@pytest.mark.parametrize("path", sorted((SRC / "commands").glob("*.py")), ids=lambda p: p.name)
def test_commands_are_thin(path):
    n = len(path.read_text().splitlines())
    assert n <= COMMAND_MAX_LINES, f"{path.name}: {n} lines (a command parses, calls, prints)"


def test_the_layer_test_sees_a_violation(tmp_path):
    """The checks are not vacuous: the table has many layers and imports are found."""
    table = layer_table()
    assert table["errors"] < table["data"] < table["nss"] < table["commands"]
    found = {mod for p in sources() for mod, _ in imports(p)}
    assert "parknss.errors" in found and len(found) > 50


# --- the tests mirror the package -----------------------------------------------------------

TESTS = ROOT / "tests"
HELPERS = TESTS / "helpers"  # the shared builders (a package on pytest's pythonpath)


def tree_files() -> list[Path]:
    """Every .py file under tests/ (test modules, conftests, helpers)."""
    return sorted(p for p in TESTS.rglob("*.py") if "__pycache__" not in p.parts)


def _is_package(folder: Path) -> bool:
    """A folder of Python modules (configs/, models/, web/static/ are package data)."""
    return folder.is_dir() and any(folder.glob("*.py"))


def test_every_test_file_lives_beside_what_it_tests():
    """tests/ mirrors src/parknss/: a test file is in tests/<unit>[/<sub>]/ where
    src/parknss/<unit>[/<sub>]/ is a package, or at the top level (a top-level module's
    tests, or cross-cutting ones; not named after a package); helpers/ holds no tests;
    nothing else but conftest.py files and the helpers."""
    files = tree_files()
    bad = []
    for p in files:
        rel = p.relative_to(TESTS)
        if rel.parts[0] == HELPERS.name:
            if p.name.startswith("test_"):
                bad.append(f"{rel}: a test module among the helpers")
            continue
        if not (p.name.startswith("test_") or p.name == "conftest.py"):
            bad.append(f"{rel}: neither a test module nor a conftest (shared code: helpers/)")
        folder = rel.parent
        if folder.parts and not _is_package(SRC / folder):
            bad.append(f"{rel}: src/parknss/{folder.as_posix()}/ is not a package")
        named = p.stem.removeprefix("test_").split("_")[0]
        if not folder.parts and _is_package(SRC / named):
            bad.append(f"{rel}: tests of the {named}/ package belong in tests/{named}/")
    assert not bad, "misplaced test files:\n" + "\n".join(bad)
    # not vacuous: most tests are in unit folders, some at the top level
    tests = [p for p in files if p.name.startswith("test_")]
    nested = [p for p in tests if p.parent != TESTS]
    assert len(tests) > 50 and len(nested) > len(tests) / 2 and len(nested) < len(tests)


def _imported_modules(path: Path) -> list[tuple[str, int]]:
    """(module, line) of every import in a file (function bodies too); relative imports
    are given with their leading dots."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = "." * node.level + (node.module or "")
            out += [(f"{mod}.{a.name}" if node.level and not node.module else mod, node.lineno)
                    for a in node.names]
    return out


def test_no_test_module_imports_another():
    """Test modules, conftests and helpers import parknss, third-party code and ``helpers``,
    never a test module or a conftest (shared builders live in helpers/, shared fixtures in
    conftest.py)."""
    bad = []
    for p in tree_files():
        in_helpers = p.is_relative_to(HELPERS)
        for mod, line in _imported_modules(p):
            parts = mod.lstrip(".").split(".")
            test_like = any(x.startswith("test_") or x == "conftest" for x in parts)
            relative = mod.startswith(".") and not in_helpers
            if test_like or relative or parts[0] == "tests":
                bad.append(f"{p.relative_to(ROOT)}:{line}: imports {mod}")
    assert not bad, "test modules importing test modules:\n" + "\n".join(bad)


def test_the_test_layout_checks_see_a_violation(tmp_path):
    """The import check is not vacuous: it finds the imports of a file like the old ones."""
    old = tmp_path / "test_old.py"
    old.write_text("from test_nss_synth import make_campaign\n\n\ndef f():\n"
                   "    import actuators_tiny, conftest\n")
    assert [m for m, _ in _imported_modules(old)] == ["test_nss_synth", "actuators_tiny",
                                                       "conftest"]
    assert {m for p in tree_files() for m, _ in _imported_modules(p)} >= {
        "helpers.synth", "parknss.cli"}
