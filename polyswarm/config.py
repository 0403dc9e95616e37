"""One typed, nested configuration object, loaded from TOML and passed explicitly.

Every section is a frozen dataclass; unknown keys are rejected with a "did you mean"
hint; values are type-checked. The effective configuration is written next to the
results of every run (``save_config``). The sections are in ``polyswarm.config_sections``.

    cfg = load_config("robot.toml")          # or Config() for the defaults
    cfg = with_overrides(cfg, {"slam": {"keyframe_distance_m": 0.3}})
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
import types
import typing
from enum import StrEnum
from pathlib import Path
from typing import Any

from polyswarm.config_sections import (
    TWO_PI,
    AgentIoConfig,
    CommandOutput,
    CommsConfig,
    Config,
    EvidenceConfig,
    ExploreConfig,
    IcpConfig,
    IcpReference,
    LidarConfig,
    LidarMount,
    LoopClosureConfig,
    MapConfig,
    NavConfig,
    OdometryNoiseConfig,
    OutOfRange,
    PersistConfig,
    Range,
    RefineConfig,
    RobotConfig,
    RobotEntry,
    SensorSource,
    SimConfig,
    SlamConfig,
    Strategy,
    SubmapConfig,
    num,
    positive,
)
from polyswarm.errors import ConfigError
from polyswarm.profiles import PROFILES

__all__ = [
    "TWO_PI",
    "AgentIoConfig",
    "CommandOutput",
    "CommsConfig",
    "Config",
    "EvidenceConfig",
    "ExploreConfig",
    "IcpConfig",
    "IcpReference",
    "LidarConfig",
    "LidarMount",
    "LoopClosureConfig",
    "MapConfig",
    "NavConfig",
    "OdometryNoiseConfig",
    "OutOfRange",
    "PersistConfig",
    "Range",
    "RefineConfig",
    "RobotConfig",
    "RobotEntry",
    "SensorSource",
    "SimConfig",
    "SlamConfig",
    "Strategy",
    "SubmapConfig",
    "num",
    "positive",
]


# ---------------------------------------------------------------------------------------
# Loading, validation, saving
# ---------------------------------------------------------------------------------------


def _check_value(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if origin in (tuple,):
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_check_value(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _check_value(v, a, f"{where}[{i}]")
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return _check_value(value, args[0], where)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, where)
    raise ConfigError(f"{where}: unsupported type {hint}")  # pragma: no cover


def _build(cls: type, data: Any, where: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"{where or 'config'}: expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in data.items():
        path = f"{where}.{key}" if where else key
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ConfigError(f"unknown key {path!r}{hint}")
        kwargs[key] = _check_value(value, hints[key], path)
        rng = fields[key].metadata.get("range")
        if rng is not None and not rng.contains(kwargs[key]):
            raise ConfigError(f"{path} must be in {rng.describe()}, got {value!r}")
    return cls(**kwargs)


def _merge_dicts(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge_dicts(out[k], v)
        else:
            out[k] = v
    return out


def config_to_dict(cfg: Any) -> dict:
    """The configuration as plain nested dicts (what ``save_config`` writes)."""
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            out[f.name] = config_to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = [config_to_dict(x) if dataclasses.is_dataclass(x) else x for x in v]
        elif v is not None:  # None: left out (TOML has no null)
            out[f.name] = v
    return out


def known_starts(robots: tuple[RobotEntry, ...]) -> dict[str, tuple[float, float, float] | None]:
    """Each robot's start in the shared frame, None where it is not known; when no start
    is known, the first robot's is the origin (its frame is the shared frame)."""
    out = {r.id: r.start for r in robots}
    if robots and all(s is None for s in out.values()):
        out[robots[0].id] = (0.0, 0.0, 0.0)
    return out


def profile_values(name: Any) -> dict:
    """The configuration values of a named profile (``polyswarm.profiles``)."""
    if not isinstance(name, str):
        raise ConfigError(f"profile: expected a string, got {name!r}")
    if name not in PROFILES:
        close = difflib.get_close_matches(name, list(PROFILES), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(
            f"profile: unknown robot profile {name!r}{hint}; known: {', '.join(PROFILES)}"
        )
    return PROFILES[name].overrides()


def config_from_dict(data: dict, cls: type = Config) -> Any:
    """Build and validate a configuration; missing keys take their defaults, or the
    values of the named ``profile`` where it sets them."""
    if cls is Config and isinstance(data, dict) and "profile" in data:
        data = _merge_dicts(profile_values(data["profile"]), data)
    cfg = _build(cls, data, "")
    validate(cfg)
    return cfg


def with_overrides(cfg: Any, overrides: dict) -> Any:
    """A copy of ``cfg`` with nested ``overrides`` applied and validated. A new
    ``profile`` replaces the old profile's values; the other overrides win over it."""
    base = config_to_dict(cfg)
    if "profile" in overrides:
        base = _merge_dicts(base, profile_values(overrides["profile"]))
    return config_from_dict(_merge_dicts(base, overrides), type(cfg))


def with_profile(cfg: Config, name: str | None) -> Config:
    """``cfg`` with the named robot profile (None: unchanged)."""
    return cfg if name is None else with_overrides(cfg, {"profile": name})


def load_config(path: str | Path | None, cls: type = Config) -> Any:
    """Load a TOML file (``None`` gives the defaults)."""
    if path is None:
        return cls()
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError as e:
        raise ConfigError(f"config file not found: {p}") from e
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: invalid TOML: {e}") from e
    try:
        return config_from_dict(data, cls)
    except ConfigError as e:
        raise ConfigError(f"{p}: {e}") from e


def save_config(cfg: Any, path: str | Path) -> None:
    import tomli_w

    Path(path).write_text(tomli_w.dumps(config_to_dict(cfg)))


def _choice(value: str, choices: type[StrEnum], where: str) -> None:
    if value not in tuple(choices):
        raise ConfigError(f"{where} must be one of {', '.join(choices)}, got {value!r}")


def _on_grid(value: float, step: float) -> bool:
    return abs(value / step - round(value / step)) < 1e-6


def validate(cfg: Config) -> None:
    """Checks that a field's own range cannot express: choices, grids, and fields that
    bound each other."""
    if not isinstance(cfg, Config):
        return
    if cfg.profile not in PROFILES:
        profile_values(cfg.profile)  # raises with the known names
    if not _on_grid(cfg.map.cell_size_m, 0.001):
        raise ConfigError(f"map.cell_size_m must be whole millimetres, got {cfg.map.cell_size_m}")
    if not _on_grid(cfg.map.whole_map_precision_m, 1e-5):
        raise ConfigError("map.whole_map_precision_m must be whole 10 um steps")
    q = cfg.slam.merge_quantum_m
    if not (q == 0 or (q >= 1e-5 and _on_grid(q, 1e-5))):
        raise ConfigError("slam.merge_quantum_m must be 0 (off) or 0.00001-0.05 m in 10 um steps")
    lid = cfg.sim.lidar
    if not lid.range_min_m < lid.range_max_m:
        raise ConfigError(
            f"sim.lidar.range_max_m ({lid.range_max_m:g} m) must exceed range_min_m "
            f"({lid.range_min_m:g} m)"
        )
    _choice(lid.out_of_range, OutOfRange, "sim.lidar.out_of_range")
    icp = cfg.slam.icp
    if icp.outlier_end_m > icp.outlier_start_m:
        raise ConfigError("slam.icp.outlier_end_m must not exceed outlier_start_m")
    nav = cfg.nav
    if nav.tight_margin_m > nav.clearance_margin_m:
        raise ConfigError("nav.tight_margin_m must not exceed clearance_margin_m")
    if nav.frontier_clearance_m > nav.obstacle_clearance_m:
        raise ConfigError(
            "nav.frontier_clearance_m must be 0 to robot_radius_m + clearance_margin_m "
            f"({nav.obstacle_clearance_m:g} m), got {nav.frontier_clearance_m}"
        )
    e = cfg.explore
    if e.max_frontier_length_m < e.min_frontier_length_m:
        raise ConfigError("explore.max_frontier_length_m must not be below min_frontier_length_m")
    _choice(e.strategy, Strategy, "explore.strategy")
    _choice(cfg.agent.source, SensorSource, "agent.source")
    _choice(cfg.agent.output, CommandOutput, "agent.output")
    _choice(cfg.slam.submap.reference, IcpReference, "slam.submap.reference")
    if cfg.agent.output == CommandOutput.NAV2 and cfg.agent.source != SensorSource.ROS2_NODE:
        raise ConfigError('agent.output = "nav2" needs agent.source = "ros2-node"')
    keys = ("scan_key", "odom_key", "tf_static_key", "tf_key", "cmd_vel_key", "goal_key")
    for name in (*keys, "nav2_action_key"):
        key = cfg.agent.key(getattr(cfg.agent, name))
        if not key or any(ch in key for ch in "*$?#") or "//" in key:
            raise ConfigError(f"agent.{name}: {key!r} is not a plain Zenoh key")
    ids = [r.id for r in cfg.robots]
    if len(set(ids)) != len(ids):
        raise ConfigError(f"robots: ids must be unique, got {ids}")
    for r in cfg.robots:
        if not r.id or not all(ch.isalnum() or ch in "_-" for ch in r.id) or len(r.id) > 32:
            raise ConfigError(f"robots: id {r.id!r} must be 1-32 letters, digits, '_' or '-'")
        if r.start is None:
            continue
        x, y, th = r.start
        if not (abs(x) <= 1e6 and abs(y) <= 1e6 and abs(th) <= TWO_PI):
            raise ConfigError(f"robots: start of {r.id} must be finite metres and radians")
    if cfg.sim.start_poses and len(cfg.sim.start_poses) != len(cfg.robots):
        raise ConfigError(
            f"sim.start_poses: {len(cfg.sim.start_poses)} poses for {len(cfg.robots)} robots"
        )
