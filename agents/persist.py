"""Persisted state of agents and the coordinator: nothing mapped is lost on a restart.

A robot agent appends each map delta to a journal before it publishes it (so what the
others have seen is always on disk; an append costs the same whatever the map's size,
while rewriting the whole map grows with it) and writes a snapshot of its whole map
every ``SNAPSHOT_EVERY`` deltas and on shutdown, which empties the journal; loading
applies the journal to the snapshot.
The coordinator writes the merged
map and every robot's map every ``COORDINATOR_PERIOD_S`` and on shutdown. Files are
written to a temporary name and renamed (atomic on POSIX): a crash mid-write leaves the
previous state. A state file that does not decode is moved aside (``.corrupt``) and
logged; the process starts with an empty map rather than not at all.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
from pathlib import Path

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import GridPolyMap
from protocols.mapcodec import decode_delta, decode_map, encode_map

log = logging.getLogger(__name__)

COORDINATOR_PERIOD_S = 5.0  # simulated or wall seconds between coordinator state writes
SNAPSHOT_EVERY = 50  # agent deltas journaled between two snapshots of the whole map


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _set_aside(path: Path, why: Exception) -> None:
    bad = path.with_name(path.name + ".corrupt")
    log.error("state file %s is unreadable (%s): moved to %s", path, why, bad.name)
    with contextlib.suppress(OSError):  # already gone: nothing to set aside
        os.replace(path, bad)


def save_map(path: Path, pmap: GridPolyMap) -> None:
    _atomic_write(path, encode_map(pmap))


def load_map(path: Path) -> GridPolyMap | None:
    if not path.exists():
        return None
    try:
        return decode_map(path.read_bytes())
    except (PolyswarmError, OSError) as e:
        _set_aside(path, e)
        return None


def agent_paths(state_dir: str | Path, robot_id: str) -> tuple[Path, Path, Path]:
    d = Path(state_dir)
    return d / f"{robot_id}.polymap", d / f"{robot_id}.json", d / f"{robot_id}.journal"


def _write_meta(meta_path: Path, robot_id: str, pose, version: int) -> None:
    meta = {"robot": robot_id, "pose": [float(v) for v in pose], "map_version": version}
    _atomic_write(meta_path, json.dumps(meta).encode())


def save_agent(state_dir: str | Path, robot_id: str, pmap: GridPolyMap, pose) -> None:
    """A snapshot of the whole map and the pose; the journal starts empty again."""
    map_path, meta_path, journal = agent_paths(state_dir, robot_id)
    save_map(map_path, pmap)
    _write_meta(meta_path, robot_id, pose, pmap.version)
    journal.unlink(missing_ok=True)


def journal_delta(state_dir: str | Path, robot_id: str, delta_bytes: bytes, pose, version) -> None:
    """Append one encoded delta (length-prefixed) to the journal, flushed to disk."""
    _, meta_path, journal = agent_paths(state_dir, robot_id)
    journal.parent.mkdir(parents=True, exist_ok=True)
    with open(journal, "ab") as f:
        f.write(len(delta_bytes).to_bytes(4, "little") + delta_bytes)
        f.flush()
        os.fsync(f.fileno())
    _write_meta(meta_path, robot_id, pose, version)


def _replay_journal(journal: Path, pmap: GridPolyMap) -> GridPolyMap:
    """The snapshot with the journal's deltas applied; a torn last record (a crash
    mid-write) ends the replay, a record that does not apply is logged and skipped."""
    if not journal.exists():
        return pmap
    data = journal.read_bytes()
    pos = 0
    while pos + 4 <= len(data):
        n = int.from_bytes(data[pos : pos + 4], "little")
        record = data[pos + 4 : pos + 4 + n]
        if len(record) < n:
            log.warning("journal %s ends in a torn record: ignored", journal)
            break
        pos += 4 + n
        try:
            pmap = pmap.apply_delta(decode_delta(record))
        except PolyswarmError as e:
            log.error("journal %s: a delta does not apply (%s): skipped", journal, e)
    return pmap


def load_agent(state_dir: str | Path, robot_id: str) -> tuple[GridPolyMap, np.ndarray] | None:
    """The persisted map (snapshot plus journal) and last pose of ``robot_id``, or None."""
    map_path, meta_path, journal = agent_paths(state_dir, robot_id)
    pmap = load_map(map_path)
    if pmap is None or not meta_path.exists():
        return None
    pmap = _replay_journal(journal, pmap)
    try:
        meta = json.loads(meta_path.read_text())
        pose = np.array(meta["pose"], dtype=float)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise ValueError(f"bad pose {meta['pose']!r}")
    except (ValueError, KeyError, TypeError, OSError) as e:
        _set_aside(meta_path, e)
        return None
    return pmap, pose


def coordinator_paths(state_dir: str | Path) -> tuple[Path, Path]:
    d = Path(state_dir)
    return d / "coordinator-merged.polymap", d / "coordinator-robots"


def save_coordinator(state_dir: str | Path, merged: GridPolyMap, robot_maps: dict) -> None:
    merged_path, robots_dir = coordinator_paths(state_dir)
    save_map(merged_path, merged)
    for rid, pmap in robot_maps.items():
        if pmap is not None:
            save_map(robots_dir / f"{rid}.polymap", pmap)


def load_coordinator(state_dir: str | Path) -> tuple[GridPolyMap | None, dict]:
    merged_path, robots_dir = coordinator_paths(state_dir)
    merged = load_map(merged_path)
    robots = {}
    if robots_dir.is_dir():
        for p in sorted(robots_dir.glob("*.polymap")):
            m = load_map(p)
            if m is not None:
                robots[p.stem] = m
    return merged, robots
