"""Messages between polyswarm processes (PROTOCOL.md section 5.2).

Every message is a msgpack map with the envelope ``t`` (type), ``v`` (protocol
version), ``src`` (sender name), ``seq`` (per-sender, per-key sequence number) and
``ts`` (timestamp, seconds: simulated time in a simulation), plus the fields of its
type. Decoding untrusted bytes raises ``ProtocolError`` and nothing else.

    data = encode(Odometry(x=1.0, y=2.0, theta=0.1), sender="sim", seq=7, stamp_s=3.2)
    env, msg = decode(data)          # Envelope(type="odom", ...), Odometry(...)
    decode(data, expect=Odometry)    # ProtocolError unless it is an Odometry

Maps and deltas (``protocols.mapcodec``) travel as ``MapChunk`` messages
(``protocols.chunks``); the base class and the field checks are in ``protocols.base``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import ClassVar

import msgpack
import numpy as np

from polyswarm.slam.scan import LaserScan
from protocols.base import (
    Envelope,
    Message,
    ProtocolError,
    blob,
    clear_sectors,
    integer,
    number,
    points,
    text,
    xy,
)
from protocols.chunks import CHUNK_BYTES, MapChunk
from protocols.frame_messages import Anchor, Priors
from protocols.keys import NAME_RE

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = CHUNK_BYTES + 4096  # anything larger is refused before parsing
MAX_BEAMS = 100_000


class RobotState(StrEnum):
    IDLE = "idle"  # no assignment
    NAVIGATING = "navigating"
    REACHED = "reached"
    UNREACHABLE = "unreachable"  # no path on the map
    STUCK = "stuck"  # a path, but no progress along it
    HOME = "home"  # back at the start after the mission


class AssignmentKind(StrEnum):
    EXPLORE = "explore"  # go to a frontier target
    HOME = "home"  # mission over: return to the start pose
    STOP = "stop"  # stand still


class MissionState(StrEnum):
    STARTING = "starting"
    EXPLORING = "exploring"
    RETURNING = "returning"
    DONE = "done"


MAX_STATUS_PATH_POINTS = 64  # a robot status carries at most this many path points
MAX_STATUS_POINTS = 256  # a coordinator status: at most this many targets (and blacklisted)


# --- messages ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Scan(Message):
    """A 2D lidar scan (sensor frame, beams counter-clockwise from ``angle_min_rad``).

    Ranges are float32 metres; a beam without a return reads as the lidar's driver
    reports it (+inf, NaN or 0). The envelope's stamp is the first beam's time; beam k
    was taken ``k * time_increment_s`` later (0: all at once), as in sensor_msgs/LaserScan.
    """

    TYPE: ClassVar[str] = "scan"
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: np.ndarray = field(repr=False)
    time_increment_s: float = 0.0
    scan_time_s: float = 0.0

    @classmethod
    def from_laserscan(cls, s: LaserScan) -> Scan:
        """The wire message of a sweep (its stamp goes in the envelope)."""
        return cls(
            s.angle_min,
            s.angle_increment,
            s.range_min,
            s.range_max,
            np.asarray(s.ranges, dtype=np.float32),
            s.time_increment,
            s.scan_time,
        )

    def body(self) -> dict:
        b = {
            "a0": self.angle_min_rad,
            "da": self.angle_increment_rad,
            "rmin": self.range_min_m,
            "rmax": self.range_max_m,
            "r": np.asarray(self.ranges_m, dtype="<f4").tobytes(),
        }
        if self.time_increment_s or self.scan_time_s:  # absent: an instant scan
            b |= {"dt": self.time_increment_s, "T": self.scan_time_s}
        return b

    @classmethod
    def from_body(cls, b: dict) -> Scan:
        raw = blob(b.get("r"), "r", 4 * MAX_BEAMS)
        if len(raw) % 4 or len(raw) < 8:
            raise ProtocolError("field 'r': expected at least 2 float32 ranges")
        ranges = np.frombuffer(raw, dtype="<f4").astype(float)
        rmin = number(b.get("rmin"), "rmin", 0.0, 1e4)
        rmax = number(b.get("rmax"), "rmax", 0.0, 1e4)
        if rmax <= rmin:
            raise ProtocolError("range_max must exceed range_min")
        if (ranges[np.isfinite(ranges)] < 0).any():
            raise ProtocolError("negative range")
        return cls(
            number(b.get("a0"), "a0", -2 * math.pi, 2 * math.pi),
            number(b.get("da"), "da", -math.pi, math.pi),
            rmin,
            rmax,
            ranges,
            number(b.get("dt", 0.0), "dt", 0.0, 1.0 / len(ranges)),  # a sweep within a second
            number(b.get("T", 0.0), "T", 0.0, 10.0),
        )


@dataclass(frozen=True)
class Odometry(Message):
    """Wheel odometry pose (odometry frame) and velocity."""

    TYPE: ClassVar[str] = "odom"
    x: float
    y: float
    theta: float
    v_mps: float = 0.0
    w_radps: float = 0.0

    def body(self) -> dict:
        return {"x": self.x, "y": self.y, "th": self.theta, "lin": self.v_mps, "ang": self.w_radps}

    @classmethod
    def from_body(cls, b: dict) -> Odometry:
        return cls(
            number(b.get("x"), "x"),
            number(b.get("y"), "y"),
            number(b.get("th"), "th", -1e3, 1e3),
            number(b.get("lin", 0.0), "lin", -100, 100),
            number(b.get("ang", 0.0), "ang", -100, 100),
        )


@dataclass(frozen=True)
class CmdVel(Message):
    """Velocity command; ``ack`` is the sequence number of the last scan the agent
    processed (-1: none), so a simulator can keep pace with slow agents."""

    TYPE: ClassVar[str] = "cmd_vel"
    v_mps: float
    w_radps: float
    ack: int = -1

    def body(self) -> dict:
        return {"lin": self.v_mps, "ang": self.w_radps, "ack": self.ack}

    @classmethod
    def from_body(cls, b: dict) -> CmdVel:
        return cls(
            number(b.get("lin"), "lin", -100, 100),
            number(b.get("ang"), "ang", -100, 100),
            integer(b.get("ack", -1), "ack", -1),
        )


@dataclass(frozen=True)
class Pose(Message):
    """A robot's SLAM pose estimate in the swarm's map frame (``frame`` 0: a robot whose
    start pose nobody gave is in a frame of its own until the ``anchor`` numbered
    ``frame`` has put it into the swarm's; ``own``: the anchor numbered ``frame``
    withdrew it from the swarm's frame, and it is in a frame of its own again)."""

    TYPE: ClassVar[str] = "pose"
    x: float
    y: float
    theta: float
    map_version: int = 0
    blocked_by: str = ""  # a robot standing in this one's way (it should give way)
    frame: int = 0  # the last anchor applied (0: none)
    # the latest scan's clear profile (``polyswarm.frames.sighting``), sent while a robot of
    # the swarm is in a frame of its own; b"": not sent
    clear: bytes = b""
    own: bool = False

    def body(self) -> dict:
        out = {"x": self.x, "y": self.y, "th": self.theta, "ver": self.map_version}
        if self.blocked_by:
            out["wait"] = self.blocked_by
        if self.frame:  # absent when 0 (and in older senders' messages)
            out["frame"] = self.frame
        if self.clear:
            out["clr"] = self.clear
        if self.own:
            out["own"] = 1
        return out

    @classmethod
    def from_body(cls, b: dict) -> Pose:
        wait = text(b.get("wait", ""), "wait")
        if wait and not NAME_RE.match(wait):
            raise ProtocolError(f"field 'wait': bad robot name {wait!r}")
        return cls(
            number(b.get("x"), "x"),
            number(b.get("y"), "y"),
            number(b.get("th"), "th", -1e3, 1e3),
            integer(b.get("ver", 0), "ver", 0),
            wait,
            integer(b.get("frame", 0), "frame", 0),
            clear_sectors(b.get("clr", b"")),
            integer(b.get("own", 0), "own", 0, 1) == 1,
        )


# a robot out of every coordinator's reach works on targets of its own, numbered from -2
# down (``agents.alone``); -1 is none
OWN_TARGET_MIN = -(2**31)


@dataclass(frozen=True)
class RobotStatus(Message):
    TYPE: ClassVar[str] = "robot-status"
    state: RobotState
    target: int = -1  # the assignment's target id being worked on
    detail: str = ""
    keyframes: int = 0
    map_version: int = 0
    bytes_sent: int = 0  # map deltas, map replies, poses and status so far
    distance_m: float = 0.0  # travelled, by odometry
    path: tuple[tuple[float, float], ...] = ()  # the rest of the planned path (for views)

    def body(self) -> dict:
        out = {
            "state": str(self.state),
            "target": self.target,
            "detail": self.detail,
            "kf": self.keyframes,
            "ver": self.map_version,
            "bytes": self.bytes_sent,
            "dist": self.distance_m,
        }
        if self.path:  # absent when the robot has none
            out["path"] = [list(p) for p in self.path]
        return out

    @classmethod
    def from_body(cls, b: dict) -> RobotStatus:
        return cls(
            text(b.get("state"), "state", RobotState),
            integer(b.get("target", -1), "target", OWN_TARGET_MIN),
            text(b.get("detail", ""), "detail"),
            integer(b.get("kf", 0), "kf", 0),
            integer(b.get("ver", 0), "ver", 0),
            integer(b.get("bytes", 0), "bytes", 0),
            number(b.get("dist", 0.0), "dist", 0.0),
            points(b.get("path", ()), "path", MAX_STATUS_PATH_POINTS),
        )


@dataclass(frozen=True)
class Assignment(Message):
    """The coordinator's order to one robot: a goal point in explored free space (and,
    for a frontier, the frontier polyline it looks at)."""

    TYPE: ClassVar[str] = "assignment"
    kind: AssignmentKind
    target: int  # target id, unique within a mission (-1 for stop)
    goal: tuple[float, float] = (0.0, 0.0)
    frontier: tuple[tuple[float, float], ...] = ()
    cost_m: float = 0.0  # planned path length the coordinator expects
    map_version: int = 0  # merged map version the assignment was made on

    def body(self) -> dict:
        return {
            "kind": str(self.kind),
            "target": self.target,
            "goal": list(self.goal),
            "frontier": [list(p) for p in self.frontier],
            "cost": self.cost_m,
            "ver": self.map_version,
        }

    @classmethod
    def from_body(cls, b: dict) -> Assignment:
        return cls(
            text(b.get("kind"), "kind", AssignmentKind),
            integer(b.get("target"), "target", -1),
            xy(b.get("goal", (0.0, 0.0)), "goal"),
            points(b.get("frontier", ()), "frontier"),
            number(b.get("cost", 0.0), "cost", 0.0),
            integer(b.get("ver", 0), "ver", 0),
        )


@dataclass(frozen=True)
class CoordinatorStatus(Message):
    TYPE: ClassVar[str] = "coordinator-status"
    state: MissionState
    robots: tuple[str, ...] = ()
    frontiers: int = 0
    map_version: int = 0
    explored_m2: float = 0.0
    cycle_ms: float = 0.0  # wall time of the last cycle (merges since the previous one included)
    bytes_sent: int = 0
    cycle_cpu_ms: float = 0.0  # the same cycle's processor time (not time spent preempted)
    targets: tuple[tuple[float, float], ...] = ()  # frontier targets' goal points (views)
    blacklisted: tuple[tuple[float, float], ...] = ()  # goals given up on (views)
    # robot map updates that did not apply since the start (a version gap: a delta lost
    # or late; a merge or correction that replayed differently), the robot maps fetched
    # whole to heal them, and those fetches' bytes
    gaps: int = 0
    fetches: int = 0
    fetch_bytes: int = 0
    # the active coordinator's name and term (standby coordinators: ``agents.leadership``)
    leader: str = ""
    term: int = 0

    def body(self) -> dict:
        out = {
            "state": str(self.state),
            "robots": list(self.robots),
            "frontiers": self.frontiers,
            "ver": self.map_version,
            "area": self.explored_m2,
            "cycle_ms": self.cycle_ms,
            "bytes": self.bytes_sent,
            "cpu_ms": self.cycle_cpu_ms,
        }
        if self.targets:  # absent when empty (and in older senders' messages)
            out["goals"] = [list(p) for p in self.targets]
        if self.blacklisted:
            out["banned"] = [list(p) for p in self.blacklisted]
        if self.gaps or self.fetches:  # absent when none (and in older senders' messages)
            out["losses"] = [self.gaps, self.fetches, self.fetch_bytes]
        if self.leader:  # absent from a coordinator without standbys' election
            out["leader"] = [self.leader, self.term]
        return out

    @classmethod
    def from_body(cls, b: dict) -> CoordinatorStatus:
        robots = b.get("robots", [])
        if not isinstance(robots, list) or len(robots) > 1000:
            raise ProtocolError("field 'robots': expected a list of names")
        for r in robots:
            if not isinstance(r, str) or not NAME_RE.match(r):
                raise ProtocolError(f"field 'robots': bad robot name {r!r}")
        losses = b.get("losses", [0, 0, 0])
        if not isinstance(losses, list) or len(losses) != 3:
            raise ProtocolError("field 'losses': expected [gaps, fetches, fetch bytes]")
        leader = b.get("leader", ["", 0])
        if (
            not isinstance(leader, list)
            or len(leader) != 2
            or not isinstance(leader[0], str)
            or (leader[0] and not NAME_RE.match(leader[0]))
        ):
            raise ProtocolError("field 'leader': expected [name, term]")
        return cls(
            text(b.get("state"), "state", MissionState),
            tuple(robots),
            integer(b.get("frontiers", 0), "frontiers", 0),
            integer(b.get("ver", 0), "ver", 0),
            number(b.get("area", 0.0), "area", 0.0),
            number(b.get("cycle_ms", 0.0), "cycle_ms", 0.0),
            integer(b.get("bytes", 0), "bytes", 0),
            number(b.get("cpu_ms", 0.0), "cpu_ms", 0.0),
            points(b.get("goals", ()), "goals", MAX_STATUS_POINTS),
            points(b.get("banned", ()), "banned", MAX_STATUS_POINTS),
            *(integer(v, f"losses[{k}]", 0) for k, v in enumerate(losses)),
            leader[0],
            integer(leader[1], "leader[1]", 0),
        )


@dataclass(frozen=True)
class Clock(Message):
    """Simulation time; ``speed`` is the achieved simulated seconds per wall second."""

    TYPE: ClassVar[str] = "clock"
    t_s: float
    speed: float = 0.0

    def body(self) -> dict:
        return {"time": self.t_s, "speed": self.speed}

    @classmethod
    def from_body(cls, b: dict) -> Clock:
        return cls(number(b.get("time"), "time", 0.0), number(b.get("speed", 0.0), "speed", 0.0))


@dataclass(frozen=True)
class Truth(Message):
    """Ground-truth poses of every simulated robot (metrics only) and collision counts."""

    TYPE: ClassVar[str] = "truth"
    poses: dict[str, tuple[float, float, float]]
    wall_collisions: int = 0
    robot_collisions: int = 0

    def body(self) -> dict:
        return {
            "poses": {k: list(v) for k, v in self.poses.items()},
            "walls": self.wall_collisions,
            "robots": self.robot_collisions,
        }

    @classmethod
    def from_body(cls, b: dict) -> Truth:
        poses = b.get("poses")
        if not isinstance(poses, dict) or len(poses) > 1000:
            raise ProtocolError("field 'poses': expected a map of robot poses")
        out = {}
        for k, v in poses.items():
            if not isinstance(k, str) or not NAME_RE.match(k):
                raise ProtocolError(f"field 'poses': bad robot name {k!r}")
            if not isinstance(v, list) or len(v) != 3:
                raise ProtocolError("field 'poses': expected [x, y, theta]")
            out[k] = (number(v[0], "x"), number(v[1], "y"), number(v[2], "th", -1e3, 1e3))
        return cls(
            out, integer(b.get("walls", 0), "walls", 0), integer(b.get("robots", 0), "robots", 0)
        )


TYPES: dict[str, type[Message]] = {
    m.TYPE: m
    for m in (
        Scan,
        Odometry,
        CmdVel,
        Pose,
        RobotStatus,
        Assignment,
        Anchor,
        Priors,
        CoordinatorStatus,
        Clock,
        Truth,
        MapChunk,
    )
}


# --- encoding ----------------------------------------------------------------------------


ENVELOPE_KEYS = frozenset({"t", "v", "src", "seq", "ts"})


def encode(msg: Message, sender: str, seq: int, stamp_s: float) -> bytes:
    out = {"t": msg.TYPE, "v": PROTOCOL_VERSION, "src": sender, "seq": seq, "ts": stamp_s}
    body = msg.body()
    if ENVELOPE_KEYS & body.keys():  # pragma: no cover - a programming error
        raise ValueError(f"{msg.TYPE} body reuses envelope keys {ENVELOPE_KEYS & body.keys()}")
    out.update(body)
    return msgpack.packb(out, use_bin_type=True)


def decode(data: bytes, expect: type[Message] | None = None) -> tuple[Envelope, Message]:
    """Envelope and message of untrusted bytes; ``ProtocolError`` on any defect."""
    if not isinstance(data, bytes | bytearray | memoryview) or len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message larger than {MAX_MESSAGE_BYTES} bytes or not bytes")
    try:
        obj = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several types for malformed input
        raise ProtocolError(f"not msgpack: {e}") from None
    if not isinstance(obj, dict):
        raise ProtocolError("not a msgpack map")
    kind = obj.get("t")
    cls = TYPES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ProtocolError(f"unknown message type {kind!r}")
    if expect is not None and cls is not expect:
        raise ProtocolError(f"expected a {expect.TYPE!r} message, got {kind!r}")
    if obj.get("v") != PROTOCOL_VERSION:
        raise ProtocolError(f"protocol version {obj.get('v')!r}, expected {PROTOCOL_VERSION}")
    src = obj.get("src")
    if not isinstance(src, str) or not NAME_RE.match(src):
        raise ProtocolError(f"bad sender {src!r}")
    seq, stamp = integer(obj.get("seq"), "seq", 0), number(obj.get("ts"), "ts", 0.0, 1e12)
    env = Envelope(kind, PROTOCOL_VERSION, src, seq, stamp)
    try:
        msg = cls.from_body(obj)
    except ProtocolError:
        raise
    except (TypeError, ValueError, KeyError, OverflowError) as e:  # belt and braces
        raise ProtocolError(f"malformed {kind!r}: {e}") from None
    return env, msg


def message_fields(cls: type[Message]) -> list[str]:
    return [f.name for f in fields(cls)]
