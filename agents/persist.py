"""Persisted state of agents and the coordinator: nothing mapped is lost on a restart.

A robot agent appends each map delta to a journal before it publishes it (so what the
others have seen is always on disk; an append costs the same whatever the map's size,
while rewriting the whole map grows with it) and writes a snapshot of its whole map
every ``SNAPSHOT_EVERY`` deltas and on shutdown, which empties the journal; loading
applies the journal to the snapshot.
The coordinator keeps the merged map and its copy of every robot's map the same way
(``CoordinatorJournal``): each delta it applies or publishes is appended, encoded as it
arrived or left, and a map is snapshotted every ``SNAPSHOT_EVERY`` deltas or when a
robot's full map replaces it (a resync). Nothing large is written at shutdown, so a
loaded machine still stops within the launcher's grace period. Files are
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
from typing import NamedTuple

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import GridPolyMap
from polyswarm.slam.odomscale import OdometryScale
from protocols.mapcodec import decode_any_map, decode_delta, encode_cells_map

log = logging.getLogger(__name__)

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
    """All cells exactly (a restored map is bit-identical, so the coordinator's copy and the
    robot's map stay the same and merges replay on it)."""
    _atomic_write(path, encode_cells_map(pmap))


def load_map(path: Path) -> GridPolyMap | None:
    if not path.exists():
        return None
    try:
        return decode_any_map(path.read_bytes())  # also a dissolved map of older versions
    except (PolyswarmError, OSError) as e:
        _set_aside(path, e)
        return None


def agent_paths(state_dir: str | Path, robot_id: str) -> tuple[Path, Path, Path]:
    d = Path(state_dir)
    return d / f"{robot_id}.polymap", d / f"{robot_id}.json", d / f"{robot_id}.journal"


class SavedAgent(NamedTuple):
    """What an agent resumes from: its map, its last pose in the map frame, the robot
    base's odometry reading at that pose (None in state written without it), the last
    anchor it applied (0: none; ``agents.anchoring``) and the odometry's distance scale
    its SLAM had learnt (None: none saved)."""

    map: GridPolyMap
    pose: np.ndarray
    odom: np.ndarray | None
    frame: int = 0
    scale: OdometryScale | None = None
    own_frame: bool = False  # that anchor withdrew the shared frame (``Anchor.own``)


def _write_meta(
    meta_path: Path,
    robot_id: str,
    pose,
    version: int,
    odom=None,
    frame: int = 0,
    scale=None,
    own_frame: bool = False,
) -> None:
    meta = {"robot": robot_id, "pose": [float(v) for v in pose], "map_version": version}
    if odom is not None:
        meta["odom"] = [float(v) for v in odom]
    if frame:
        meta["frame"] = int(frame)
    if own_frame:
        meta["own_frame"] = True
    if scale is not None:
        meta["odometry_scale"] = scale.state()
    _atomic_write(meta_path, json.dumps(meta).encode())


def save_agent(
    state_dir: str | Path,
    robot_id: str,
    pmap: GridPolyMap,
    pose,
    odom=None,
    frame: int = 0,
    scale: OdometryScale | None = None,
    own_frame: bool = False,
) -> None:
    """A snapshot of the whole map and the pose; the journal starts empty again.

    ``odom``: the robot base's odometry at ``pose``. The base keeps counting while the
    agent is down, so a restarted agent predicts where the robot went since. ``frame``:
    the last anchor applied (the map and pose are in the shared frame since). ``scale``:
    the odometry's distance scale SLAM learnt (a restarted agent keeps it)."""
    map_path, meta_path, journal = agent_paths(state_dir, robot_id)
    save_map(map_path, pmap)
    _write_meta(meta_path, robot_id, pose, pmap.version, odom, frame, scale, own_frame)
    journal.unlink(missing_ok=True)


def save_pose(
    state_dir: str | Path,
    robot_id: str,
    pose,
    version: int,
    odom=None,
    frame=0,
    scale=None,
    own_frame: bool = False,
) -> None:
    """The last pose only (shutdown: the map is already on disk, snapshot plus journal)."""
    meta_path = agent_paths(state_dir, robot_id)[1]
    _write_meta(meta_path, robot_id, pose, version, odom, frame, scale, own_frame)


def _append(journal: Path, delta_bytes: bytes) -> None:
    """Append one encoded delta (length-prefixed) to a journal, flushed to disk."""
    journal.parent.mkdir(parents=True, exist_ok=True)
    with open(journal, "ab") as f:
        f.write(len(delta_bytes).to_bytes(4, "little") + delta_bytes)
        f.flush()
        os.fsync(f.fileno())


def journal_delta(
    state_dir: str | Path,
    robot_id: str,
    delta_bytes: bytes,
    pose,
    version,
    odom=None,
    frame=0,
    scale=None,
    own_frame: bool = False,
) -> None:
    """Append one encoded delta of the agent's map to its journal, and its pose."""
    _, meta_path, journal = agent_paths(state_dir, robot_id)
    _append(journal, delta_bytes)
    _write_meta(meta_path, robot_id, pose, version, odom, frame, scale, own_frame)


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


def load_agent(state_dir: str | Path, robot_id: str) -> SavedAgent | None:
    """The persisted map (snapshot plus journal), last pose and odometry of ``robot_id``,
    or None."""
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
        odom = meta.get("odom")
        if odom is not None:
            odom = np.array(odom, dtype=float)
            if odom.shape != (3,) or not np.isfinite(odom).all():
                raise ValueError(f"bad odometry {meta['odom']!r}")
        frame = meta.get("frame", 0)
        if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
            raise ValueError(f"bad frame {frame!r}")
        own_frame = meta.get("own_frame", False)
        if not isinstance(own_frame, bool):
            raise ValueError(f"bad own_frame {own_frame!r}")
    except (ValueError, KeyError, TypeError, OSError) as e:
        _set_aside(meta_path, e)
        return None
    return SavedAgent(pmap, pose, odom, frame, _scale(meta, meta_path), own_frame)


def _scale(meta: dict, meta_path: Path) -> OdometryScale | None:
    """The saved odometry scale; a bad one is dropped (learnt again), not the pose."""
    state = meta.get("odometry_scale")
    if state is None:
        return None
    try:
        return OdometryScale.from_state(state)
    except ValueError as e:
        log.warning("%s: %s; the odometry scale is learnt again", meta_path, e)
        return None


def coordinator_paths(state_dir: str | Path) -> tuple[Path, Path]:
    d = Path(state_dir)
    return d / "coordinator-merged.polymap", d / "coordinator-robots"


class CoordinatorJournal:
    """The coordinator's state on disk, written as it changes (owned by one coordinator).

    Per map (the merged map, and the coordinator's copy of each robot's map): a snapshot
    and a journal of the encoded deltas applied since. ``load_coordinator`` reads them
    back."""

    def __init__(self, state_dir: str | Path) -> None:
        self.merged_path, self.robots_dir = coordinator_paths(state_dir)
        self._journaled: dict[Path, int] = {}  # snapshot -> deltas in its journal

    def merged(self, delta_bytes: bytes, pmap: GridPolyMap) -> None:
        """The merged map's delta ``delta_bytes`` was applied, giving ``pmap``."""
        self._record(self.merged_path, delta_bytes, pmap)

    def robot_delta(self, robot_id: str, delta_bytes: bytes, pmap: GridPolyMap) -> None:
        """A robot's delta was applied to the coordinator's copy, giving ``pmap``."""
        self._record(self.robots_dir / f"{robot_id}.polymap", delta_bytes, pmap)

    def robot_map(self, robot_id: str, pmap: GridPolyMap) -> None:
        """A robot's full map replaced the coordinator's copy (a resync)."""
        self._record(self.robots_dir / f"{robot_id}.polymap", None, pmap)

    def robot_withdrawn(self, robot_id: str) -> None:
        """A robot's copy left the merged map (its frame was found wrong,
        ``agents.anchoring``): its snapshot and journal move to ``withdrawn/`` (kept, not
        restored: a restarted coordinator must not merge it again)."""
        snapshot = self.robots_dir / f"{robot_id}.polymap"
        aside = self.robots_dir / "withdrawn"
        aside.mkdir(parents=True, exist_ok=True)
        n = len(list(aside.glob(f"{robot_id}-*.polymap")))
        for src in (snapshot, snapshot.with_suffix(".journal")):
            if src.exists():
                os.replace(src, aside / f"{robot_id}-{n}{src.suffix}")
        self._journaled.pop(snapshot, None)

    def _record(self, snapshot: Path, delta_bytes: bytes | None, pmap: GridPolyMap) -> None:
        n = self._journaled.get(snapshot, 0)
        if delta_bytes is None or n >= SNAPSHOT_EVERY or not snapshot.exists():
            # snapshot first, then drop the journal: a crash in between leaves old deltas
            # that replay onto the newer snapshot as no-ops
            save_map(snapshot, pmap)
            snapshot.with_suffix(".journal").unlink(missing_ok=True)
            self._journaled[snapshot] = 0
        else:
            _append(snapshot.with_suffix(".journal"), delta_bytes)
            self._journaled[snapshot] = n + 1


def record(journal: CoordinatorJournal | None, what: str, *args) -> None:
    """``journal.what(*args)`` if the coordinator keeps state; a full disk is logged, and
    must not stop the mission (the coordinator's thread and its replay processes)."""
    if journal is None:
        return
    try:
        getattr(journal, what)(*args)
    except OSError as e:
        log.error("could not write the coordinator's state: %s", e)


def load_coordinator(state_dir: str | Path) -> tuple[GridPolyMap | None, dict]:
    """The merged map and the robots' maps a coordinator wrote (snapshots plus journals)."""
    merged_path, robots_dir = coordinator_paths(state_dir)
    merged = load_map(merged_path)
    if merged is not None:
        merged = _replay_journal(merged_path.with_suffix(".journal"), merged)
    robots = {}
    if robots_dir.is_dir():
        for p in sorted(robots_dir.glob("*.polymap")):
            m = load_map(p)
            if m is not None:
                robots[p.stem] = _replay_journal(p.with_suffix(".journal"), m)
    return merged, robots
