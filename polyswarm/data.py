"""Where the shared test data lives (``../shared/data`` next to the repository)."""

from __future__ import annotations

import os
from pathlib import Path

from polyswarm.errors import DataFormatError

ENV_VAR = "POLYSWARM_DATA"
WORLDS = ("loop", "cross", "zigzag", "maze")  # the thesis's benchmark terrains


def shared_data_dir() -> Path:
    """``$POLYSWARM_DATA`` or ``<repo>/../shared/data``; raises if it does not exist."""
    env = os.environ.get(ENV_VAR)
    path = Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"
    if not path.is_dir():
        raise DataFormatError(
            f"shared data folder not found at {path} (set {ENV_VAR} to the folder with "
            "worlds/ and logs/)"
        )
    return path


def world_yaml(name: str) -> Path:
    p = shared_data_dir() / "worlds" / f"{name}.yaml"
    if not p.exists():
        raise DataFormatError(f"world map not found: {p}")
    return p


def log_paths() -> list[Path]:
    return sorted((shared_data_dir() / "logs").glob("*.log.gz"))
