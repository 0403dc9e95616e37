"""The swarm's joint pose graph: robots correct each other, not only themselves.

Each robot optimises its own pose graph; where two robots mapped the same walls, the
coordinator knows better than either: it holds every robot's keyframe polygons (the
merges it replays) at their current poses (the corrections it replays). This module
builds one graph over all of them:

* **inter-robot edges**: a keyframe's walls and those of its neighbours in time
  (``WINDOW_KEYFRAMES``, within ``LOCAL_RADIUS_M``) placed on another robot's walls
  nearby by a correlative search (``SEED_WINDOW_*``: unless another place fits nearly
  as well) and point-to-line ICP (``polyswarm.frames.mapmatch.align_walls``), accepted when the
  walls agree (``MIN_INLIERS``, ``MIN_INLIER_SHARE``), pin the pose in both directions
  (``MIN_CONDITION``: not a corridor) and the fix is local (``MAX_FIX_*``: frames are
  found by ``agents.anchoring`` first, or told; this refines them);
* **nodes**: one per robot, where its map lies against where it is now, the reference
  robot's (the one whose frame is the map's) fixed. Each edge measures one robot's
  node against another's (Huber loss: a wrong edge is down-weighted). A robot's map is
  moved as a whole: its own pose graph bends it, the swarm places it.

The keyframes that inter-robot edges hold, moved with their robot's solution, go back
to it as *priors* (``solve``): it adds them to its own graph (``PoseGraph.set_priors``)
and its map follows its graph as after a loop closure. A robot whose edges disagree
(its map bent by drift, or wrong edges) is left where it is.

    ledgers = {"r1": KeyframeLedger(), "r2": KeyframeLedger()}
    ... ledgers[rid].merged(kid, polygon); ledgers[rid].corrected(moves) ...
    joint = JointGraph()
    joint.find_edges(ledgers)
    priors = joint.solve(ledgers, reference="r1")   # robot -> keyframe -> pose
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.frames.mapmatch import (
    INLIER_M,
    NORMAL_WEIGHT_M,
    Walls,
    align_walls,
    wall_points,
    wall_tree,
)
from polyswarm.polymap import TypedPolygon, VectorType
from polyswarm.se2 import compose, inverse, relative, transform_points, wrap
from polyswarm.slam.follow import REACH_M, QPose, frame_of, pose_of
from polyswarm.slam.loopsearch import correlative_search
from polyswarm.slam.posegraph import PoseGraph

log = logging.getLogger(__name__)

# a keyframe is matched with the walls of its neighbours in time: a keyframe polygon is
# trimmed to what it added to the map, often a few metres of wall
WINDOW_KEYFRAMES = 6  # keyframes either side of it
LOCAL_RADIUS_M = 5.0  # ... whose walls' centre lies this close to its own
TARGET_MARGIN_M = 2.0  # the other robot's keyframes this much farther out are matched on
KEYFRAME_STEP = 3  # every third keyframe is matched (its neighbours share its walls)
MAX_TRIES = 4  # a keyframe with no edge is tried this often at most (as the others map near)
MIN_WALL_POINTS = 60  # 6 m of wall in the local view (points every 0.1 m)
MIN_INLIERS = 50  # 5 m of it within INLIER_M of the other robot's walls after ICP
MIN_INLIER_SHARE = 0.8  # of the local view's points near the other's walls (0.5 m)
NEAR_M = 0.5  # a local view's point this close to the other's walls overlaps them
# smaller over larger eigenvalue of the agreeing points' normals' scatter: walls in one
# direction only (a corridor) leave the position along them to the odometry
MIN_CONDITION = 0.1
# a local view is first placed by a correlative search within this window (a start
# told 0.58 m and 5 deg off puts walls 5 m out a metre off), then refined by ICP
SEED_WINDOW_M = 1.0
SEED_WINDOW_RAD = math.radians(8.0)
MAX_FIX_M = 1.5  # a fix farther than this is another place, not a refinement
MAX_FIX_RAD = math.radians(10.0)
# ICP from where the maps already put the view settles elsewhere with this share of the
# fix's agreeing points or more: the walls do not choose (a corridor with a few doors;
# TurtleBot3s at the office's start were slid 1.1 m along it by such edges)
RIVAL_SHARE = 0.9
RIVAL_M = 0.2  # ... farther than this from the fix, or turned RIVAL_RAD from it
RIVAL_RAD = math.radians(2.0)
# an edge as a measure of where one robot's map lies against another's: the ICP's
# agreement, and a turn's error carried out over the keyframes' spread
RIGID_SIGMA_M = 0.10
RIGID_SIGMA_RAD = math.radians(0.5)
MIN_EDGES = 3  # a robot is placed on at least this many edges, not on one match
# the edges of a robot placed must agree: the median misfit at the solution at most this
# (a map bent by its own drift, or wrong edges, is left to the robot's own graph)
CONSISTENT_M = 0.15
# priors are sent for a robot when the joint graph moves one of its held keyframes this
# far (a turn counts at follow.REACH_M, as corrections do)
PRIOR_MOVE_M = 0.03
# a prior in the robot's own graph: where the swarm placed that keyframe, as sure as the
# walls that placed it agree (the ICP's INLIER_M and the maps' noise)
PRIOR_SIGMA_M = 0.05
PRIOR_SIGMA_RAD = math.radians(0.5)


@dataclass(frozen=True)
class LedgerKeyframe:
    frame: QPose  # where its polygon is held (wire units): moved by every correction
    walls: Walls  # its obstacle vectors' wall points, in that frame's coordinates
    centre: np.ndarray  # the mean of its wall points, in that frame's coordinates


def _keyframe(polygon: TypedPolygon, frame: QPose) -> LedgerKeyframe:
    s, e, t = polygon.segments()
    keep = t == VectorType.OBSTACLE
    w = wall_points(s[keep], e[keep])
    back = inverse(pose_of(frame))
    walls = transform_points(back, w.walls) if len(w.walls) else w.walls
    c, sn = math.cos(back[2]), math.sin(back[2])
    normals = w.normals @ np.array([[c, sn], [-sn, c]])
    centre = walls.mean(axis=0) if len(walls) else np.zeros(2)
    return LedgerKeyframe(frame, Walls(walls, normals), centre)


class KeyframeLedger:
    """A robot's keyframes as the coordinator replays them: each polygon's walls and the
    frame it is held at now. Cheaper than an atlas (no cells), and kept beside it, so a
    replay pool may hold the atlas in another process."""

    def __init__(self) -> None:
        self.keyframes: dict[int, LedgerKeyframe] = {}
        self.corrections = 0  # corrections that moved a keyframe held here

    def __len__(self) -> int:
        return len(self.keyframes)

    def merged(self, kid: int, polygon: TypedPolygon) -> None:
        """A replayed merge of keyframe ``kid`` (held at ``frame_of`` its polygon)."""
        self.keyframes[kid] = _keyframe(polygon, frame_of(polygon))

    def corrected(self, moves) -> None:
        """A replayed correction: (keyframe, step of its frame in wire units) pairs."""
        moved = False
        for kid, (dx, dy, dth) in moves:
            k = self.keyframes.get(kid)
            if k is not None:
                f = (k.frame[0] + dx, k.frame[1] + dy, k.frame[2] + dth)
                self.keyframes[kid] = LedgerKeyframe(f, k.walls, k.centre)
                moved = True
        self.corrections += moved

    @classmethod
    def from_atlas(cls, atlas) -> KeyframeLedger:
        """The ledger of a map handed over whole with its atlas (``polyswarm.slam.follow``)."""
        out = cls()
        for kid, polygon in atlas.polygons.items():
            out.keyframes[kid] = _keyframe(polygon, atlas.poses[kid])
        return out

    def snapshot(self) -> dict[int, LedgerKeyframe]:
        """The keyframes now (entries are immutable: safe to read on another thread)."""
        return dict(self.keyframes)


@dataclass(frozen=True)
class InterEdge:
    a: tuple[str, int]  # the robot and keyframe whose walls were matched on
    b: tuple[str, int]  # the robot and keyframe matched
    z: np.ndarray  # b's frame seen from a's frame
    inliers: int


def _placed(k: LedgerKeyframe) -> Walls:
    """A keyframe's wall points and normals where its frame is now."""
    p = pose_of(k.frame)
    if not len(k.walls.walls):
        return k.walls
    c, s = math.cos(p[2]), math.sin(p[2])
    return Walls(transform_points(p, k.walls.walls), k.walls.normals @ np.array([[c, s], [-s, c]]))


def _centre(k: LedgerKeyframe) -> np.ndarray:
    return transform_points(pose_of(k.frame), k.centre[None])[0]


def _centres(kfs: dict[int, LedgerKeyframe]) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe ids (ascending) and where their walls' centres are now."""
    ids = np.array(sorted(kfs), dtype=int)
    xy = np.array([_centre(kfs[k]) for k in ids]).reshape(-1, 2)
    return ids, xy


def _gather(kfs: dict[int, LedgerKeyframe], ids) -> Walls:
    parts = [w for w in (_placed(kfs[k]) for k in ids) if len(w.walls)]
    if not parts:
        return Walls(np.zeros((0, 2)), np.zeros((0, 2)))
    return Walls(
        np.concatenate([w.walls for w in parts]), np.concatenate([w.normals for w in parts])
    )


def match_keyframe(
    mine: dict[int, LedgerKeyframe],
    kid: int,
    theirs: dict[int, LedgerKeyframe],
    their_centres: tuple[np.ndarray, np.ndarray] | None = None,
    my_centres: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[int, np.ndarray, int] | None:
    """Keyframe ``kid``'s local view (its walls and its neighbours', placed where they
    are) on another robot's walls nearby: (their keyframe nearest it, ``kid``'s frame
    seen from that keyframe's frame, agreeing wall points), or None when the walls do
    not pin it down (see the module)."""
    ids, xy = my_centres if my_centres is not None else _centres(mine)
    centre = _centre(mine[kid])
    near_t = (np.abs(ids - kid) <= WINDOW_KEYFRAMES) & (
        np.hypot(*(xy - centre).T) <= LOCAL_RADIUS_M
    )
    local = _gather(mine, ids[near_t])
    if len(local.walls) < MIN_WALL_POINTS:
        return None
    t_ids, t_xy = their_centres if their_centres is not None else _centres(theirs)
    d = np.hypot(*(t_xy - centre).T) if len(t_ids) else np.zeros(0)
    near = t_ids[d <= LOCAL_RADIUS_M + TARGET_MARGIN_M]
    if len(near) == 0:
        return None
    target = _gather(theirs, near)
    if len(target.walls) < MIN_WALL_POINTS:
        return None
    seed = _seed(target, local, centre)
    if seed is None:  # another place fits nearly as well: a corridor, repeated rooms
        return None
    tree = wall_tree(target)
    fix = align_walls(target, local, seed, tree)
    if math.hypot(fix[0], fix[1]) > MAX_FIX_M or abs(wrap(fix[2])) > MAX_FIX_RAD:
        return None
    inliers, share, condition = _agreement(tree, local, fix)
    if inliers < MIN_INLIERS or share < MIN_INLIER_SHARE or condition < MIN_CONDITION:
        return None
    if _rivalled(target, local, tree, fix, inliers):
        return None
    a_kid = int(near[np.argmin(d[d <= LOCAL_RADIUS_M + TARGET_MARGIN_M])])
    b_now = pose_of(mine[kid].frame)
    z = relative(pose_of(theirs[a_kid].frame), compose(fix, b_now))
    return a_kid, z, inliers


def _seed(target: Walls, local: Walls, centre: np.ndarray) -> np.ndarray | None:
    """The correlative search's best fix of the local view (turning about its centre),
    as a pose applied to its points; None when it is ambiguous."""
    guess, _, ambiguous = correlative_search(
        local.walls - centre,
        (centre[0], centre[1], 0.0),
        target.walls,
        target.walls,
        SEED_WINDOW_M,
        0.1,
        SEED_WINDOW_RAD,
        math.radians(1.0),
    )
    if ambiguous:
        return None
    return compose(guess, (-centre[0], -centre[1], 0.0))


def _rivalled(target: Walls, local: Walls, tree, fix: np.ndarray, inliers: int) -> bool:
    """Whether ICP from no fix at all (the view where the maps hold it) settles on
    another fix that the walls agree with nearly as well (``RIVAL_SHARE``)."""
    here = align_walls(target, local, np.zeros(3), tree)
    apart = math.hypot(*(here[:2] - fix[:2])) > RIVAL_M or abs(wrap(here[2] - fix[2])) > RIVAL_RAD
    return apart and _agreement(tree, local, here)[0] >= RIVAL_SHARE * inliers


def _agreement(tree, local: Walls, fix: np.ndarray) -> tuple[int, float, float]:
    """After ``fix``: the local points within ``INLIER_M`` of a same-facing wall of the
    target (``tree``: its ``wall_tree``), their share of the points within ``NEAR_M``
    of one, and the condition of their normals (1: walls in all directions, 0: all
    parallel)."""
    c, s = math.cos(fix[2]), math.sin(fix[2])
    q = transform_points(fix, local.walls)
    nq = local.normals @ np.array([[c, s], [-s, c]])
    d, _ = tree.query(np.hstack([q, NORMAL_WEIGHT_M * nq]), distance_upper_bound=NEAR_M)
    near = np.isfinite(d)
    good = d <= INLIER_M
    if good.sum() < 2:
        return int(good.sum()), 0.0, 0.0
    n = nq[good]
    ev = np.linalg.eigvalsh(n.T @ n)
    return int(good.sum()), float(good.sum() / max(near.sum(), 1)), float(ev[0] / max(ev[1], 1e-12))


@dataclass
class JointGraph:
    """Inter-robot edges found so far (kept: an edge joins two rigid keyframes, whatever
    their poses become) and the solve over all robots' keyframes."""

    edges: dict[tuple[str, int], InterEdge] = field(default_factory=dict)
    # keyframes matched without an edge: (times, the other robots' keyframes near it
    # then); tried again only when more came near (the others mapped on)
    tries: dict[tuple[str, int], tuple[int, int]] = field(default_factory=dict)

    def find_edges(self, ledgers: dict[str, dict[int, LedgerKeyframe]]) -> int:
        """Match every ``KEYFRAME_STEP``-th keyframe of each robot without an edge on
        each robot before it in name order (again, at most ``MAX_TRIES`` times, once
        more of their keyframes are near it); the edges found."""
        found = 0
        names = sorted(ledgers)
        centres = {r: _centres(ledgers[r]) for r in names}
        reach = LOCAL_RADIUS_M + TARGET_MARGIN_M
        for bi, b in enumerate(names):
            mine = ledgers[b]
            ids, xy = centres[b]
            for kid, centre in zip(ids, xy, strict=True):
                key = (b, int(kid))
                if kid % KEYFRAME_STEP or key in self.edges:
                    continue
                near = {
                    a: int((np.hypot(*(centres[a][1] - centre).T) <= reach).sum())
                    for a in names[:bi]
                    if len(centres[a][0])
                }
                n_near = sum(near.values())
                times, seen = self.tries.get(key, (0, 0))
                if n_near <= seen or times >= MAX_TRIES:
                    continue
                for a in (a for a, n in near.items() if n):
                    hit = match_keyframe(mine, int(kid), ledgers[a], centres[a], centres[b])
                    if hit is not None:
                        a_kid, z, n = hit
                        self.edges[key] = InterEdge((a, a_kid), key, z, n)
                        found += 1
                        break
                if key not in self.edges:
                    self.tries[key] = (times + 1, n_near)
        return found

    def solve(
        self, ledgers: dict[str, dict[int, LedgerKeyframe]], reference: str
    ) -> dict[str, dict[int, np.ndarray]]:
        """Where the joint solution puts the keyframes that inter-robot edges hold (frame
        poses, metres and radians), per robot other than the reference; robots joined to
        the reference by no edge, by fewer than ``MIN_EDGES``, or whose edges disagree
        (``CONSISTENT_M``) are left out.

        Each robot's map moves as one rigid body (one node per robot, the reference's
        fixed): a robot's own pose graph bends its map, the swarm only places it. (Every
        keyframe a node of its own, with soft chains, bent a TurtleBot3's map by 0.5 m
        priors it could not follow, solve after solve: office seed 1, median pose error
        1.5 m against 0.4 m without the joint graph.)"""
        edges = [
            e
            for e in self.edges.values()
            if e.a[1] in ledgers.get(e.a[0], {}) and e.b[1] in ledgers.get(e.b[0], {})
        ]
        robots = _joined(reference, edges, ledgers)
        if len(robots) < 2:
            return {}
        order = [reference, *sorted(robots - {reference})]  # node 0: the reference
        # turns about the keyframes' centre, not the map origin (a lever of tens of metres)
        held = sorted({e.a for e in edges} | {e.b for e in edges})
        c = np.mean([pose_of(ledgers[r][k].frame)[:2] for r, k in held], axis=0)
        pivot = np.array([c[0], c[1], 0.0])
        g = PoseGraph()
        node = {r: g.add_node(np.zeros(3)) for r in order}
        between = []  # (robot a, robot b, inv(T_a) T_b as the edge measures it)
        for e in edges:
            if e.a[0] not in robots or e.b[0] not in robots:
                continue
            pa, pb = pose_of(ledgers[e.a[0]][e.a[1]].frame), pose_of(ledgers[e.b[0]][e.b[1]].frame)
            z = compose(inverse(pivot), compose(pa, compose(e.z, compose(inverse(pb), pivot))))
            between.append((e.a[0], e.b[0], z))
            g.add_edge(node[e.a[0]], node[e.b[0]], z, RIGID_SIGMA_M, RIGID_SIGMA_RAD, loop=True)
        frames = g.optimise()
        out: dict[str, dict[int, np.ndarray]] = {}
        for r in order[1:]:
            mine = [(a, b, z) for a, b, z in between if r in (a, b)]
            misfit = [_misfit(relative(frames[node[a]], frames[node[b]]), z) for a, b, z in mine]
            if len(mine) < MIN_EDGES or float(np.median(misfit)) > CONSISTENT_M:
                log.info(
                    "joint pose graph: %s left where it is (%d edges, median misfit %.2f m)",
                    r,
                    len(mine),
                    float(np.median(misfit)) if misfit else 0.0,
                )
                continue
            move = compose(pivot, compose(frames[node[r]], inverse(pivot)))
            for rr, kid in held:
                if rr == r:
                    out.setdefault(r, {})[kid] = compose(move, pose_of(ledgers[r][kid].frame))
        return out


def _misfit(a: np.ndarray, b: np.ndarray) -> float:
    """How far apart two poses are, metres (a turn counted at ``REACH_M``)."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + REACH_M * abs(float(wrap(a[2] - b[2])))


def moved_m(ledger: dict[int, LedgerKeyframe], poses: dict[int, np.ndarray]) -> float:
    """How far ``poses`` move the farthest-moved keyframe (a turn counts at ``REACH_M``)."""
    return max((_misfit(p, pose_of(ledger[kid].frame)) for kid, p in poses.items()), default=0.0)


def _joined(reference: str, edges: list[InterEdge], ledgers) -> set[str]:
    """The robots an inter-robot edge joins to the reference, directly or through others."""
    if reference not in ledgers or not ledgers[reference]:
        return set()
    out, grew = {reference}, True
    while grew:
        grew = False
        for e in edges:
            ra, rb = e.a[0], e.b[0]
            if (ra in out) != (rb in out):
                out |= {ra, rb}
                grew = True
    return out
