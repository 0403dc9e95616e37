"""Imports point one way: core <- protocols <- agents; sim stays independent of agents.

The ``polyswarm`` command (``polyswarm.cli``, ``polyswarm.benchmarks``) is the
composition root and may import everything; zenoh and pybullet are imported nowhere
else outside ``agents`` and ``sim``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMAND = ("polyswarm.cli", "polyswarm.benchmarks", "polyswarm.runners")


def imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
    return out


def modules(package: str):
    for p in sorted((ROOT / package).rglob("*.py")):
        name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        yield name, imports(p)


def top(names: set[str]) -> set[str]:
    return {n.split(".")[0] for n in names}


def test_core_imports_no_protocols_agents_sim_zenoh_or_pybullet():
    for name, imps in modules("polyswarm"):
        if name.startswith(COMMAND):
            continue
        bad = top(imps) & {"protocols", "agents", "sim", "zenoh", "pybullet"}
        assert not bad, f"{name} imports {bad}"


def test_protocols_import_only_the_core():
    for name, imps in modules("protocols"):
        bad = top(imps) & {"agents", "sim", "zenoh", "pybullet"}
        assert not bad, f"{name} imports {bad}"


def test_sim_is_independent_of_agents_protocols_and_zenoh():
    for name, imps in modules("sim"):
        bad = top(imps) & {"agents", "protocols", "zenoh"}
        assert not bad, f"{name} imports {bad}"
        assert not any(i.startswith(COMMAND) for i in imps), name


def test_agents_do_not_import_the_simulator_or_the_command():
    for name, imps in modules("agents"):
        assert "sim" not in top(imps) and "pybullet" not in top(imps), name
        assert not any(i.startswith(COMMAND) for i in imps), name


def _module_graph(package: str, root: Path = ROOT) -> dict[str, set[str]]:
    """Which modules of ``package`` each of its modules imports (function-level imports
    included, ``if TYPE_CHECKING:`` blocks not: they never run). A package is its
    ``__init__``."""
    files = sorted((root / package).rglob("*.py"))
    key = {
        p: ".".join(p.relative_to(root).with_suffix("").parts).removesuffix(".__init__")
        for p in files
    }
    names = set(key.values())
    graph = {}
    for p in files:
        name = key[p]
        tree = ast.parse(p.read_text())
        skip = {
            id(n)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
            for n in ast.walk(node)
        }
        deps = set()
        for node in ast.walk(tree):
            if id(node) in skip or not isinstance(node, ast.ImportFrom | ast.Import):
                continue
            targets = (
                [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            )
            for target in filter(None, targets):
                t = target
                while t and t not in names:
                    t = t.rpartition(".")[0]
                if t and t != name:
                    deps.add(t)
        graph[name] = deps
    return graph


def test_the_core_has_no_import_cycles():
    graph = {
        k: {d for d in v if not d.startswith(COMMAND)}
        for k, v in _module_graph("polyswarm").items()
        if not k.startswith(COMMAND)
    }
    done: set[str] = set()

    def visit(node: str, path: list[str]) -> None:
        if node in path:
            raise AssertionError("import cycle: " + " -> ".join([*path[path.index(node) :], node]))
        if node in done:
            return
        for dep in graph.get(node, ()):
            if dep != "polyswarm":
                visit(dep, [*path, node])
        done.add(node)

    for node in graph:
        visit(node, [])


SIZED = ("polyswarm", "agents", "protocols", "sim", "tests", "examples")
MAX_MODULE_LINES = 600  # a module a newcomer reads in one sitting
MAX_FUNCTION_LINES = 80  # a function that does one thing fits on a screen or two


def _sources():
    for package in SIZED:
        yield from sorted((ROOT / package).rglob("*.py"))


def test_no_module_is_over_600_lines_and_no_function_over_80():
    long_modules = [
        f"{p.relative_to(ROOT)}: {n}"
        for p in _sources()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    ]
    long_functions = [
        f"{p.relative_to(ROOT)}:{node.lineno} {node.name}: {node.end_lineno - node.lineno + 1}"
        for p in _sources()
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]
    assert not long_modules, long_modules
    assert not long_functions, long_functions


def test_no_test_module_imports_another():
    """Helpers shared by tests live in conftest.py."""
    bad = [
        f"{p.name}: {name}"
        for p in sorted((ROOT / "tests").glob("*.py"))
        for name in imports(p)
        if name.startswith("tests.test_")
    ]
    assert not bad, bad
