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
