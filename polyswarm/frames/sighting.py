"""Would one robot have seen the other there? Evidence for a frame from outside the maps.

Two robots' maps of a building that looks the same after a quarter turn (a ring
corridor, a cross) fit each other equally well at the true frame and at its rotated
images: no check on the two maps alone can tell them apart (``polyswarm.frames.mapmatch``).
What breaks the symmetry is that the robots were *somewhere* at every moment, and lidars
see robots. A frame predicts where robot B stood, in A's map, at each moment A
scanned; if the prediction falls well inside what A's scan saw free at that moment, A
would have seen B there and did not: the frame is contradicted.

Each robot sends, with its poses, a *clear profile* of its latest scan: for each of
``SECTORS`` equal sectors around it, the distance to the nearest return in that sector
(``CLEAR_UNIT_M`` steps, rounded down; 0 for a sector without a return). Within that
distance, the sector held nothing the lidar sees: no robot. ``contradictions`` counts
the moments where a frame puts the other robot, anywhere within ``NEAR_M`` of where it
predicts it, inside the viewer's clear sectors. Given the viewer's map (``Room``), only
the places of that disc where a robot can stand count: along a corridor the disc
always reaches a wall, whose returns would otherwise hide every prediction.

``seen`` counts the opposite, positive evidence: a return where the frame puts the other
robot, clear of the viewer's walls. A frame is committed only when the robots have seen
each other in a few places where it puts them (``distinct_places``;
``polyswarm.frames.estimate.FrameEstimate``); robots exploring apart seldom see each other, so
the coordinator sends a waiting robot towards where its candidate frame puts the others
(``agents.anchoring``).

Assumed: robots are visible to each other's lidars (true of the simulator's robots and
of TurtleBot-class robots, whose lidar heads sit at the same height), and the robots'
clocks agree to a fraction of a second (simulated time, or NTP on real robots).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from polyswarm.se2 import compose, inverse, transform_points

SECTORS = 128  # 2.8 degrees each: along a 2 m corridor a sector is clear for 20 m
CLEAR_UNIT_M = 0.2  # one byte per sector: up to 51 m
# where a frame puts a robot it may be anywhere this close: the two robots' SLAM poses
# disagree by up to 0.9 m (office launch, seed 1: 12 moments contradicted the true frame
# with a 0.5 m disc, none with this one), and their pose stamps by up to half a second
NEAR_M = 0.8
# nearer than this the bearing of a prediction says nothing (two such errors)
MIN_SIGHT_M = 2 * NEAR_M
# a robot whose map a correction moved farther than this sent its earlier poses from a
# frame that far off: sightings forget them (a stale pose must not contradict the truth)
SIGHTING_SLACK_M = 0.25
PROFILE_PERIOD_S = 1.0  # a robot sends its clear profile with at most one pose a second
MAX_GAP_S = 1.5  # poses farther apart than this are not interpolated between
TRACK_LEN = 8000  # poses kept per robot (an hour at 2 Hz)
# moments that contradict a frame before it is left out: one could be a stale pose or a
# glitch of timing; three are not (a false one would let a rival image stand alone)
MIN_CONTRADICTIONS = 3
# a robot's body reaches this far from its pose (the simulator's 0.2 m, a TurtleBot4's
# 0.17 m): the return it makes is nearer than its pose by up to this
BODY_M = 0.3
# a return at least this far from every wall of the viewer's map is not a wall: a sector
# 2.8 degrees wide places a return up to 0.25 m aside at 10 m, and wrong frames' best
# predictions along corridors met returns up to 0.55 m (once 0.86 m) from the map's walls
# (bench merge's loop and cross, seed 0)
WALL_CLEAR_M = 0.6
# a robot's centre is at least this far from a wall of the map it stands in (TurtleBot3
# Burger: 0.105 m; map walls are line fits, a few centimetres off)
ROOM_CLEAR_M = 0.1
# where a frame puts a robot, the viewer may have mapped its body (a wall and a shadow):
# within this of the prediction the robot may stand wherever its own map lets it. Only
# the body's reach: farther, a wrong frame's prediction inside the viewer's walls would
# stand there too, and go uncontradicted
FOOTPRINT_M = BODY_M + ROOM_CLEAR_M
# sightings count in places this far apart: a quarter turn (or more) about a point moves a
# place within 0.8 m of it by at most 1.1 m (NEAR_M + BODY_M), a sighting's reach; three
# places 1.5 m apart cannot all lie within 0.8 m of one point (their circle: 0.87 m)
SEEN_APART_M = 1.5
# the return's place within its sector is unknown: a sector 2.8 degrees wide spans
# d x 0.049 m at range d (0.49 m at 10 m, 1.46 m at 30 m). A sighting counts only if the
# whole arc of the sector at the return's range lies explored and this far clear of the
# viewer's walls: a wall's return has its wall on that arc. Its margin is the map's wall
# error (bench slam: 3-8 cm) and a correction's drift since the scan (SIGHTING_SLACK_M).
# A wrong frame of the cross was committed on a wall's return at 30 m, 0.73 m from the
# sector's centre to its wall (launch at unknown starts, seed 0); a 15 m cap on range
# kept it out and delayed six right frames in corridors by 1-38 matches
# (launch-sightings.json); the arc keeps it out at any range. On bench merge's recorded
# pairs (merge-sight-arc.json) right poses seen in 3 places: 14 of 53 as with the cap;
# wrong poses seen at all: 0 of 141 (a margin of 0.15-0.25 m was tried instead)
ARC_CLEAR_M = 0.25
ARC_STEP_M = 0.1  # the arc is tested at points this far apart
ROOM_RES_M = 0.1  # the raster of where a robot can stand
DISC_STEP_M = 0.2  # the disc around a prediction is tried at places this far apart


def clear_profile(xy: np.ndarray, blind: np.ndarray = ()) -> bytes:
    """The clear profile of a scan: ``xy`` (n, 2) its returns, metres in the robot frame;
    ``blind`` the bearings (radians, robot frame) of beams that might have hit something
    and not said so (dropouts: a dark robot may be one). Per sector, the distance to its
    nearest return in ``CLEAR_UNIT_M`` steps, rounded down, capped at 255; 0 where a
    sector has no return or a blind beam in it or its neighbours (nothing is known)."""
    out = np.full(SECTORS, 256, dtype=np.int64)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(xy):
        d = np.hypot(xy[:, 0], xy[:, 1])
        units = np.minimum(np.floor(d / CLEAR_UNIT_M), 255).astype(np.int64)
        np.minimum.at(out, _sector(np.arctan2(xy[:, 1], xy[:, 0])), units)
    out[out == 256] = 0
    blind_s = np.unique(_sector(np.asarray(blind, dtype=float)))
    for k in (-1, 0, 1):  # a beam's bearing is not de-skewed: a sector to either side
        out[(blind_s + k) % SECTORS] = 0
    return bytes(out.astype(np.uint8))


def _sector(bearing: np.ndarray) -> np.ndarray:
    u = (np.asarray(bearing) + math.pi) / (2 * math.pi)
    return (np.floor(u * SECTORS).astype(np.int64)) % SECTORS


@dataclass(frozen=True)
class Sighting:
    """A robot's pose at a moment, with its scan's clear profile (b"" if not sent)."""

    t_s: float
    pose: tuple[float, float, float]
    clear: bytes = b""


class Track:
    """A robot's poses over time in one frame, with the clear profiles sent with them."""

    def __init__(self) -> None:
        self._items: deque[Sighting] = deque(maxlen=TRACK_LEN)

    def __len__(self) -> int:
        return len(self._items)

    def add(self, s: Sighting) -> None:
        if self._items and s.t_s < self._items[-1].t_s:
            return  # late: the track stays in time order
        if s.clear and len(s.clear) != SECTORS:
            s = Sighting(s.t_s, s.pose, b"")
        self._items.append(s)

    def since(self, t_s: float) -> Track:
        """A copy of the poses from ``t_s`` on."""
        out = Track()
        out._items.extend(s for s in self._items if s.t_s >= t_s)
        return out

    def until(self, t_s: float) -> Track:
        """A copy of the poses up to ``t_s``."""
        out = Track()
        out._items.extend(s for s in self._items if s.t_s <= t_s)
        return out

    def moved(self, frame) -> Track:
        """The track in another frame: each pose composed with ``frame`` (x m, y m, rad)."""
        out = Track()
        for s in self._items:
            pose = tuple(float(v) for v in compose(frame, s.pose))
            out._items.append(Sighting(s.t_s, pose, s.clear))
        return out

    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        t = np.fromiter((s.t_s for s in self._items), float, len(self._items))
        xy = np.array([s.pose[:2] for s in self._items], dtype=float).reshape(-1, 2)
        return t, xy

    def paths(self) -> list[np.ndarray]:
        """Where the robot went: its positions as polylines ((n, 2) each), split where
        poses are more than ``MAX_GAP_S`` apart."""
        if not self._items:
            return []
        t, xy = self._arrays()
        cut = np.flatnonzero(np.diff(t) > MAX_GAP_S) + 1
        return np.split(xy, cut)

    def positions_at(self, times: np.ndarray) -> np.ndarray:
        """(n, 2) positions at ``times``, interpolated; NaN where no two poses within
        ``MAX_GAP_S`` bracket a time."""
        out = np.full((len(times), 2), np.nan)
        if len(self._items) < 2:
            return out
        t, xy = self._arrays()
        k1 = np.clip(np.searchsorted(t, times, side="right"), 1, len(t) - 1)
        k0 = k1 - 1
        gap = t[k1] - t[k0]
        ok = (times >= t[0]) & (times <= t[-1]) & (gap <= MAX_GAP_S)
        w = np.where(gap > 0, (times - t[k0]) / np.where(gap > 0, gap, 1.0), 0.0)
        mid = xy[k0] + w[:, None] * (xy[k1] - xy[k0])
        out[ok] = mid[ok]
        return out

    def views(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (n,), poses (n, 3), clear distances in metres (n, SECTORS)) of the
        poses sent with a clear profile."""
        kept = [s for s in self._items if s.clear]
        t = np.fromiter((s.t_s for s in kept), float, len(kept))
        poses = np.array([s.pose for s in kept], dtype=float).reshape(-1, 3)
        clear = np.frombuffer(b"".join(s.clear for s in kept), dtype=np.uint8)
        return t, poses, clear.reshape(-1, SECTORS).astype(float) * CLEAR_UNIT_M


class Room:
    """Where a robot's centre can be in a map: its explored free space, at least
    ``ROOM_CLEAR_M`` from walls, as a raster (``ROOM_RES_M``; 20-30 ms for a 300 m2
    map), built once per map matched."""

    def __init__(self, pmap) -> None:
        from scipy.ndimage import binary_erosion

        if pmap.explored_area() <= 0.0:  # nowhere to stand
            self.origin, self.grid = np.zeros(2), np.zeros((1, 1), dtype=bool)
            return
        x0, y0, x1, y1 = pmap.bounds()
        self.origin = np.array([x0, y0], dtype=float)
        nx = max(1, math.ceil((x1 - x0) / ROOM_RES_M))
        ny = max(1, math.ceil((y1 - y0) / ROOM_RES_M))
        ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        centres = self.origin + (np.column_stack([ix.ravel(), iy.ravel()]) + 0.5) * ROOM_RES_M
        free = pmap.is_free_many(centres).reshape(nx, ny)
        r = math.ceil(ROOM_CLEAR_M / ROOM_RES_M)
        disk = np.hypot(*np.mgrid[-r : r + 1, -r : r + 1]) <= r
        self.grid = binary_erosion(free, disk, border_value=0)

    def allows(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) points (metres) -> True where a robot's centre could be."""
        ij = np.floor((np.asarray(xy, float).reshape(-1, 2) - self.origin) / ROOM_RES_M)
        ij = ij.astype(np.int64)
        inside = (ij >= 0).all(axis=1) & (ij < self.grid.shape).all(axis=1)
        out = np.zeros(len(ij), dtype=bool)
        out[inside] = self.grid[ij[inside, 0], ij[inside, 1]]
        return out


# offsets (metres) a disc of radius NEAR_M is sampled at
_DISC = np.array(
    [
        (x, y)
        for x in np.arange(-NEAR_M, NEAR_M + 1e-9, DISC_STEP_M)
        for y in np.arange(-NEAR_M, NEAR_M + 1e-9, DISC_STEP_M)
        if math.hypot(x, y) <= NEAR_M
    ]
)


# the disc's offsets within a robot's footprint (``FOOTPRINT_M``)
_IN_FOOTPRINT = np.hypot(_DISC[:, 0], _DISC[:, 1]) <= FOOTPRINT_M


def unseen(
    viewer: Track, other: Track, frame, room: Room | None = None, other_room: Room | None = None
) -> int:
    """Moments where ``frame`` (the other robot's frame in the viewer's, x m, y m, rad)
    puts the other robot where the viewer's scan saw clear: anywhere within ``NEAR_M`` of
    the predicted position, the robot would have been nearer than the nearest return of
    its sector.

    Without ``room`` every sector the disc reaches must be clear beyond the disc: a wall
    within ``NEAR_M`` of the prediction hides it, and along a corridor that is every
    prediction. With ``room`` (the viewer's map, ``Room``) only the disc's places where a
    robot can stand count: each must lie within its sector's clear distance.
    ``other_room`` (the other robot's map, in its frame) adds the places within
    ``FOOTPRINT_M`` of the prediction where its own map lets it stand: the viewer mapped
    the other's body where it stood (as a wall, with a shadow behind), so in the viewer's
    map alone only the places beside the body were left, all in clear view past it, and
    the truth was contradicted at the moments the robots saw each other (loop launch,
    seed 0: two waiting robots 10.6 m apart)."""
    return len(unseen_where(viewer, other, frame, room, other_room)[0])


def unseen_where(
    viewer: Track, other: Track, frame, room: Room | None = None, other_room: Room | None = None
):
    """``unseen``'s moments, as evidence for a log: (times (n,) seconds, the viewer's
    poses (n, 3), where the frame put the other robot (n, 2), metres, viewer's frame)."""
    pred = _predictions(viewer, other, frame)
    if pred is None:
        return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 2))
    t, poses, clear, p, d, bearing = pred
    if room is not None:
        other = None if other_room is None else (other_room, inverse(np.asarray(frame, float)))
        hit = _unseen_in_room(poses, clear, p, room, other)
        return t[hit], poses[hit], p[hit]
    rows = np.arange(len(d))
    half = np.arcsin(NEAR_M / d)  # the disc's half-angle as the viewer sees it
    step = 2 * math.pi / SECTORS
    nearest = np.minimum(  # every sector the disc reaches: its two edges and between
        clear[rows, _sector(bearing - half)], clear[rows, _sector(bearing + half)]
    )
    for k in range(1, int(np.ceil(half.max() / step)) + 1):
        for a in (bearing - k * step, bearing + k * step):
            got = clear[rows, _sector(a)]
            nearest = np.where(k * step < half, np.minimum(nearest, got), nearest)
    nearest = np.minimum(nearest, clear[rows, _sector(bearing)])
    hit = nearest > d + NEAR_M
    return t[hit], poses[hit], p[hit]


def _predictions(viewer: Track, other: Track, frame):
    """The viewer's moments where ``frame`` places the other robot far enough away for a
    bearing to mean something: (times (n,), viewer poses (n, 3), clear distances (n, SECTORS),
    predicted positions (n, 2), their distances (n,) and bearings in the viewer's frame
    (n,)); None if there is none."""
    t, poses, clear = viewer.views()
    if not len(t):
        return None
    p = transform_points(np.asarray(frame, float), other.positions_at(t))
    rel = p - poses[:, :2]
    d = np.hypot(rel[:, 0], rel[:, 1])
    ok = np.isfinite(d) & (d > MIN_SIGHT_M)
    if not ok.any():
        return None
    bearing = np.arctan2(rel[ok, 1], rel[ok, 0]) - poses[ok, 2]
    return t[ok], poses[ok], clear[ok], p[ok], d[ok], bearing


def _unseen_in_room(
    poses: np.ndarray, clear: np.ndarray, p: np.ndarray, room: Room, other=None
) -> np.ndarray:
    """``unseen`` with the disc cut to where a robot can stand (see there): per
    prediction, contradicted or not. ``other``: (the other robot's ``Room``, the
    viewer's frame in its frame)."""
    n, m = len(p), len(_DISC)
    pts = (p[:, None, :] + _DISC[None, :, :]).reshape(-1, 2)
    can = room.allows(pts)
    if other is not None:  # its body's footprint, where its own map lets it stand
        body = np.flatnonzero(np.tile(_IN_FOOTPRINT, n))
        can[body] |= other[0].allows(transform_points(other[1], pts[body]))
    can = can.reshape(n, m)
    rel = pts.reshape(n, m, 2) - poses[:, None, :2]
    dist = np.hypot(rel[..., 0], rel[..., 1])
    bearing = np.arctan2(rel[..., 1], rel[..., 0]) - poses[:, 2:3]
    got = np.take_along_axis(clear, _sector(bearing), axis=1)
    would_see = (got > dist) & (dist > MIN_SIGHT_M / 2)
    # contradicted: somewhere to stand, and the scan would have seen the robot at each
    return can.any(axis=1) & (would_see | ~can).all(axis=1)


def seen(viewer: Track, other: Track, frame, no_wall: Callable[[np.ndarray], np.ndarray]) -> int:
    """Moments where the viewer's scan had a return where ``frame`` (the other robot's
    frame in the viewer's, x m, y m, rad) puts the other robot (within ``NEAR_M``, its
    body ``BODY_M``) and its map has no wall there: the other robot, seen."""
    return len(seen_where(viewer, other, frame, no_wall))


def seen_where(
    viewer: Track,
    other: Track,
    frame,
    no_wall: Callable[..., np.ndarray],
    max_range_m: float = math.inf,
    arc: bool = True,
) -> np.ndarray:
    """``seen``'s moments as the places (n, 2) (metres, the viewer's frame) where the
    frame put the other robot.

    ``no_wall``: (n, 2) points in the viewer's frame and a clearance (metres) -> True
    where a point lies in the viewer's explored space farther than that from its walls
    (``no_wall_test``). A return counts where the frame puts the other robot if the
    sector's centre at the return's range, and the space a robot's width behind it, lie
    ``WALL_CLEAR_M`` clear of walls and, with ``arc``, the sector's whole arc there
    ``ARC_CLEAR_M`` clear. A frame's prediction that meets an unexplained
    return again and again is positive evidence; silence (no return, or a wall) is none.
    Predictions farther than ``max_range_m`` are not looked at (no cap by default: the
    arc test grows with range)."""
    pred = _predictions(viewer, other, frame)
    if pred is None:
        return np.zeros((0, 2))
    _, poses, clear, p, d, bearing = pred
    near = d <= max_range_m
    if not near.any():
        return np.zeros((0, 2))
    poses, clear, p, d, bearing = poses[near], clear[near], p[near], d[near], bearing[near]
    rows = np.arange(len(d))
    half = np.arcsin(NEAR_M / d)
    step = 2 * math.pi / SECTORS
    miss = np.full(len(rows), np.inf)  # per moment: how far the nearest return of the
    got = np.zeros((len(rows), 2))  # disc's sectors is from the prediction; its range, bearing
    reach = int(np.ceil(half.max() / step))
    for k in range(-reach, reach + 1):
        s = _sector(bearing + k * step)
        r = clear[rows, s] + CLEAR_UNIT_M / 2  # the return's range, to half a step
        m = np.where(clear[rows, s] > 0, np.abs(r - d), np.inf)
        better = (abs(k) * step <= half) & (m < miss)
        miss = np.where(better, m, miss)
        got[better] = np.column_stack([r, (s + 0.5) * step - math.pi])[better]
    hit = miss <= NEAR_M + BODY_M
    if not hit.any():
        return np.zeros((0, 2))
    origin, rng, heading = poses[hit, :2], got[hit, 0], poses[hit, 2] + got[hit, 1]
    # the return and the space just behind it (a robot's width on) are both clear of the
    # viewer's walls: a wall's return has its wall, and what lies behind it unexplored
    ok = _clear_behind(no_wall, origin, rng, heading, WALL_CLEAR_M)
    if arc:  # the sector's arc at the return's range: no wall on it
        for i in np.flatnonzero(ok):
            n = max(2, math.ceil(rng[i] * step / ARC_STEP_M) + 1)
            sweep = heading[i] + np.linspace(-step / 2, step / 2, n)
            on_arc = origin[i] + rng[i] * np.column_stack([np.cos(sweep), np.sin(sweep)])
            ok[i] = no_wall(on_arc, ARC_CLEAR_M).all()
    return p[hit][ok]


def _clear_behind(no_wall, origin, rng, heading, clear_m: float) -> np.ndarray:
    """Per ray (origin (n, 2), range (n,), heading (n,)): its point at the range and the
    point a robot's width (``2 * BODY_M``) behind lie ``clear_m`` clear of walls."""
    ray = np.column_stack([np.cos(heading), np.sin(heading)])
    q = origin + rng[:, None] * ray
    ok = no_wall(np.vstack([q, q + 2 * BODY_M * ray]), clear_m)
    return ok[: len(q)] & ok[len(q) :]


def no_wall_test(pmap, clear_m: float = WALL_CLEAR_M) -> Callable[[np.ndarray], np.ndarray]:
    """``seen``'s map test on ``pmap`` (a GridPolyMap): explored and clear of walls
    (by ``clear_m`` metres, or the clearance the test is called with)."""

    def no_wall(xy: np.ndarray, clear: float = clear_m) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = pmap.is_free_many(xy)
        for i in np.flatnonzero(out):
            out[i] = pmap.nearest_obstacle_distance(xy[i, 0], xy[i, 1], clear) > clear
        return out

    return no_wall


def contradictions(a: Track, b: Track, frame, rooms: tuple[Room, Room] | None = None) -> int:
    """Moments where ``frame`` (B's frame in A's) puts either robot in the other's clear
    view: A's scans looking for B, and B's scans looking for A. ``rooms``: A's and B's
    maps as ``Room`` (see ``unseen``)."""
    return len(contradicted_where(a, b, frame, rooms))


def contradicted_where(
    a: Track, b: Track, frame, rooms: tuple[Room, Room] | None = None
) -> np.ndarray:
    """``contradictions``' moments, as evidence for a log: rows of (time s, viewer 0 for
    A or 1 for B, the viewer's x, y and where the frame put the other's x, y), metres in
    A's frame."""
    frame = np.asarray(frame, dtype=float)
    ra, rb = rooms if rooms is not None else (None, None)
    rows = []
    for viewer, (t, poses, p) in enumerate(
        (unseen_where(a, b, frame, ra, rb), unseen_where(b, a, inverse(frame), rb, ra))
    ):
        at, there = poses[:, :2], p
        if viewer == 1:  # B's frame to A's
            at, there = transform_points(frame, at), transform_points(frame, there)
        rows.append(np.column_stack([t, np.full(len(t), viewer), at, there]))
    return np.vstack(rows)


def mutual_seen(
    a: Track, b: Track, frame, maps, max_range_m: float = math.inf, arc: bool = True
) -> np.ndarray:
    """Where either robot saw the other where ``frame`` (B's frame in A's) puts it
    (``seen_where`` both ways): the seen robot's places (n, 2), metres, in A's frame.
    ``maps``: A's and B's GridPolyMaps. Count them with ``distinct_places``."""
    frame = np.asarray(frame, dtype=float)
    b_seen = seen_where(a, b, frame, no_wall_test(maps[0]), max_range_m, arc)  # B, in A's
    a_seen = seen_where(b, a, inverse(frame), no_wall_test(maps[1]), max_range_m, arc)
    return np.vstack([b_seen, transform_points(frame, a_seen)])


def distinct_places(xy: np.ndarray) -> int:
    """How many of the places ``xy`` (n, 2) lie at least ``SEEN_APART_M`` apart (greedy).

    Places, not moments: a frame and its image under a rotation of the building (a
    cross's quarter turn about its centre) put a robot in the same place only near the
    rotation's centre. Seen there again and again, the robots tell the two apart no
    better than seen once; seen in places a few metres apart, they do."""
    places: list[np.ndarray] = []
    for p in np.asarray(xy, dtype=float).reshape(-1, 2):
        if all(math.dist(p, q) >= SEEN_APART_M for q in places):
            places.append(p)
    return len(places)
