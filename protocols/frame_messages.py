"""Messages that place a robot's frame in the swarm's (PROTOCOL.md 5.2): the
coordinator's ``Anchor`` of a robot's frame and a robot's pose-graph ``Priors``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from protocols.base import Message, ProtocolError, integer, number

MAX_ANCHOR_M = 1e5  # a frame farther than 100 km is not in the same building


@dataclass(frozen=True)
class Anchor(Message):
    """The coordinator to a robot whose start pose nobody gave: where its frame lies in
    the swarm's map frame, found by matching its map with the merged map. The robot
    moves its pose graph, keyframes and pose by it (its map follows as a correction)
    and from then on speaks in the swarm's frame. ``frame`` numbers the anchors sent to
    this robot (from 1): one already applied is ignored, so it can be sent again.

    ``own``: the frame the robot was anchored to so far was found wrong (later
    evidence contradicted it) and is withdrawn. The robot moves nothing (``x``, ``y``,
    ``theta`` are 0): the coordinates it speaks in become a frame of its own again,
    until the next anchor.

    ``team``: the pose is of the robot's frame in the frame of another robot whose frame
    is not known either (their maps were matched with each other): the robot moves as
    for any anchor, but the coordinates it speaks in are that team's frame, not the
    shared one (its poses say ``own``), until the next anchor places the team."""

    TYPE: ClassVar[str] = "anchor"
    frame: int
    x: float
    y: float
    theta: float
    own: bool = False
    team: bool = False

    def body(self) -> dict:
        b = {"frame": self.frame, "x": self.x, "y": self.y, "th": self.theta}
        if self.own:
            b["own"] = 1
        if self.team:
            b["team"] = 1
        return b

    @classmethod
    def from_body(cls, b: dict) -> Anchor:
        own = integer(b.get("own", 0), "own", 0, 1) == 1
        team = integer(b.get("team", 0), "team", 0, 1) == 1
        a = cls(
            integer(b.get("frame"), "frame", 1),
            number(b.get("x"), "x", -MAX_ANCHOR_M, MAX_ANCHOR_M),
            number(b.get("y"), "y", -MAX_ANCHOR_M, MAX_ANCHOR_M),
            number(b.get("th"), "th", -1e3, 1e3),
            own,
            team,
        )
        if own and (a.x, a.y, a.theta) != (0.0, 0.0, 0.0):
            raise ProtocolError("field 'own': a withdrawn frame moves nothing (x, y, th 0)")
        if own and team:
            raise ProtocolError("fields 'own' and 'team': a withdrawal joins no team")
        return a


MAX_PRIORS = 4096  # keyframes one priors message may hold (12 bytes each, about 50 KB)
MAX_PRIOR_MM = 10**8  # 100 km in millimetres


@dataclass(frozen=True)
class Priors(Message):
    """The coordinator to a robot: where the swarm's joint pose graph
    (``polyswarm.frames.jointgraph``) puts some of its keyframes. ``poses``: (keyframe id, x,
    y in millimetres, theta in 10 microradians) of the frame each keyframe's polygon is
    held at (as in a correction), ids ascending; ``sigma_m``, ``sigma_rad``: their
    standard deviations. They replace the robot's earlier priors; it holds them in its
    pose graph and its map follows at its next keyframe, sent as a correction like any
    other. ``frame``: the anchor the poses are in (0: the robot's start was given); a
    robot in another frame ignores them, as it ignores keyframes it does not know."""

    TYPE: ClassVar[str] = "priors"
    frame: int
    sigma_m: float
    sigma_rad: float
    poses: tuple[tuple[int, int, int, int], ...]

    def body(self) -> dict:
        return {
            "frame": self.frame,
            "sm": self.sigma_m,
            "sr": self.sigma_rad,
            "p": [list(p) for p in self.poses],
        }

    @classmethod
    def from_body(cls, b: dict) -> Priors:
        raw = b.get("p")
        if not isinstance(raw, list) or len(raw) > MAX_PRIORS:
            raise ProtocolError(f"field 'p': a list of at most {MAX_PRIORS} priors")
        poses, last = [], -1
        for item in raw:
            if not isinstance(item, list) or len(item) != 4:
                raise ProtocolError("field 'p': each prior is [keyframe, x, y, theta]")
            kid = integer(item[0], "keyframe", last + 1, 2**31)
            x = integer(item[1], "x", -MAX_PRIOR_MM, MAX_PRIOR_MM)
            y = integer(item[2], "y", -MAX_PRIOR_MM, MAX_PRIOR_MM)
            th = integer(item[3], "theta", -400_000, 400_000)  # within +-4 rad
            poses.append((kid, x, y, th))
            last = kid
        return cls(
            integer(b.get("frame"), "frame", 0),
            number(b.get("sm"), "sm", 1e-4, 100.0),
            number(b.get("sr"), "sr", 1e-6, 10.0),
            tuple(poses),
        )
