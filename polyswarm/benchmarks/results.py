"""Committed benchmark results: ``docs/results/NAME.json``, each with where it came from.

Every headline figure in the README names one of these files and the key it reads;
``tests/test_readme_figures.py`` checks that the README and the files agree.

    save("bandwidth", result)   # -> docs/results/bandwidth.json, with result["meta"]
    value = lookup(load("bandwidth"), "runs.aces-corrected.delta_bytes_ratio_vs_best_baseline")
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

from polyswarm.errors import PolyswarmError

RESULTS_DIR = Path(__file__).resolve().parents[2] / "docs" / "results"


def machine_meta() -> dict:
    """Code version (git), processor model, core count, date and the command line."""
    root = RESULTS_DIR.parents[1]
    try:
        version = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        version = "unknown"
    return {
        "code_version": version,
        "cpu_model": _cpu_model(),
        "cores": os.cpu_count(),
        "date": datetime.date.today().isoformat(),
        "command": " ".join(["polyswarm", *sys.argv[1:]]),
    }


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def save(name: str, result: dict, directory: Path = RESULTS_DIR) -> Path:
    """Write ``result`` with a ``meta`` entry to ``directory/name.json``."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.json"
    path.write_text(json.dumps({**result, "meta": machine_meta()}, indent=2, default=float))
    return path


def load(name: str, directory: Path = RESULTS_DIR) -> dict:
    path = directory / f"{name}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise PolyswarmError(f"result file {path}: {e}") from e


def lookup(result: dict, key: str):
    """The value at a dotted ``key`` (``runs.aces-corrected.keyframes``; ``runs.0.x``
    indexes a list); a name that holds a dot itself (``methods.akaze_conf1.0.wrong``) is
    found as one."""
    node, parts = result, key.split(".")
    while parts:
        if isinstance(node, list) and parts[0].isdigit() and int(parts[0]) < len(node):
            node, parts = node[int(parts[0])], parts[1:]  # ``runs.0.t99_s``: the first run
            continue
        if not isinstance(node, dict):
            raise PolyswarmError(f"no {key!r} in the result ({parts[0]!r} missing)")
        for n in range(len(parts), 0, -1):  # the longest name that is there
            name = ".".join(parts[:n])
            if name in node:
                node, parts = node[name], parts[n:]
                break
        else:
            raise PolyswarmError(f"no {key!r} in the result ({parts[0]!r} missing)")
    return node
