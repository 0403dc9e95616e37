"""Where is another robot's map in ours? Two PolyMaps registered with no pose prior.

Robots whose start poses nobody measured build maps in frames of their own. This finds
the pose of map B's frame in map A's frame, or says why it cannot:

1. *Search* (``polyswarm.frames.mapsearch``). Both maps are rasterised at ``RESOLUTION_M``:
   A's walls as a hit score (a Gaussian of the distance to its obstacle vectors) and
   A's *clear* space (explored, and deeper inside it than ``CLEAR_M``); B the same. For
   every heading on a ``HEADING_STEP_RAD`` grid, every translation is scored: B's walls
   on A's walls, minus ``CONFLICT_WEIGHT`` x (B's walls in A's clear space + A's walls
   in B's clear space); coarse first, the best candidates then at full resolution.
   Free space is what makes PolyMaps good at this: a wall seen through space the other
   robot drove through is evidence against a pose.
2. *Refine.* The best peaks (``PEAKS``, apart by ``PEAK_APART_M``) are refined by
   point-to-line ICP of B's wall points on A's walls (the next ones too, while the
   robots' sightings contradict every one so far).
3. *Verify.* At the refined pose: the explored overlap, the length of wall both maps
   agree on, and the share of each map's walls standing in the other's clear space.
   A match is accepted only with enough overlap and agreeing wall, few conflicts, no
   other pose where the maps also fit without contradiction (a symmetric building: the
   wrong image of a ring corridor may overlap more than the truth), no other peak
   nearly as good elsewhere (repeated rooms), and no image of the pose under a symmetry
   of either map (where a map fits itself) that neither the maps nor the robots'
   sightings rule out.

    m = match_maps(a, b)   # m.accepted, m.pose (B's frame in A's), m.reason, evidence

The coordinator does not trust one match: see ``FrameEstimate`` for the agreement it
asks of successive matches before a robot's map is merged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import shapely
import shapely.affinity
from PIL import Image, ImageDraw
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from polyswarm.errors import PolyswarmError
from polyswarm.frames.mapsearch import (  # noqa: F401 (the search's constants, used here and re-exported)
    CONFLICT_WEIGHT,
    HEADING_STEP_RAD,
    PEAK_APART_M,
    PEAKS,
    RESOLUTION_M,
)
from polyswarm.frames.mapsearch import close as _close
from polyswarm.frames.mapsearch import search as coarse_to_fine
from polyswarm.frames.sighting import BODY_M
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType
from polyswarm.se2 import compose, inverse, transform_points, wrap
from polyswarm.slam.icp import sample_vectors

HIT_SIGMA_M = 0.15  # a wall point this far from the other's wall scores exp(-1/2)
CLEAR_M = 0.30  # explored space deeper than this inside is "clear" (noise, corners)
WALL_STEP_M = 0.10  # wall points are sampled this far apart (agreeing length = count x step)

ICP_ITERATIONS = 25
ICP_OUTLIER_M = (0.6, 0.15)  # correspondence cut-off, from the search's blur to the noise
NORMAL_WEIGHT_M = 0.3  # opposite wall faces are 0.6 m apart in the matching space
ICP_MAX_SHIFT_M = 3.0  # ICP that wanders farther from the search's pose has diverged

# A wall that another robot saw where a robot stood is the robot's body, not a building's
# wall; the robot's own map is clear there (it stood there). So a wall of one map lying
# wholly within this of where the other map's robots went is no conflict (one reaching
# out of that band is the building's), and the search does not count clear space there.
# The loop launch at unknown starts, seed 1 (thesis sensor): all 47 wall points standing
# in the other map's clear space at the true frame lay within 0.22 m of a robot's path,
# and the true frame was refused for 1.7-3.7 % conflicts for 150 s while a wrong one
# stood at 0.0-0.5 %. Over the frames logged in that launch and two office ones, at the
# final maps: the right ones' conflicts fell from 0.0-1.1 % to 0.0-0.25 %, the wrong
# ones' by at most 3 percentage points (6 of 23 changed)
TRODDEN_M = BODY_M
INLIER_M = 0.15  # a wall point this close to the other's wall agrees with it
MIN_OVERLAP_M2 = 10.0  # explored area both maps share, at least (about two rooms' worth)
MIN_AGREEING_WALL_M = 12.0  # wall length both maps see in the same place, at least
MIN_AGREEING_SHARE = 0.5  # of the walls inside the shared space, at least this share agree
MAX_CONFLICT_SHARE = 0.01  # of the walls in the shared space, at most this share stand in
# the other's clear space (a 5 m shift along the office's row of rooms: 4-8 %)
# ... a pose refused only for conflicts up to this share is still proposed for the robots'
# sightings to confirm: SLAM drift bends a map by that much (office seed 0 at unknown
# starts: the right frame at 2.4 % for 150 s, never merged). bench merge's refusals for
# conflicts up to 3 %: 30 right poses, 14 of them seen in 3 places or more; 19 wrong, none
# seen in more than 1 (merge-seen.json)
PROPOSE_CONFLICT_SHARE = 0.03
VERIFY_CONFLICT_WEIGHT = 10.0  # a wall in the other's clear space undoes ten agreeing points
MAX_RIVAL_RATIO = 0.85  # another pose (> RIVAL_APART) scoring this share of the best: ambiguous
# ... and the best must explain this much more wall than any other pose: in a row of
# identical rooms a small map fits several places almost equally (office, 3 of 3 wrong
# poses seen had a margin under 3.5 m; the right ones grew past 6 m as the maps grew)
MIN_MARGIN_WALL_M = 6.0
RIVAL_APART_M = 1.0
RIVAL_APART_RAD = math.radians(10.0)


class MatchError(PolyswarmError):
    """The maps cannot be matched at all (one of them holds no walls)."""


@dataclass(frozen=True)
class MapMatch:
    """The pose of B's frame in A's (x m, y m, theta rad) and the evidence for it."""

    pose: np.ndarray
    accepted: bool
    reason: str  # why not accepted ("" when accepted)
    overlap_m2: float
    agreeing_wall_m: float
    agreeing_share: float
    conflict_share: float
    rival_ratio: float  # the best other pose's score / this one's
    score: float
    candidates: int = field(default=0)
    margin_wall_m: float = 0.0  # wall this pose explains beyond the best other pose
    # the refined poses with their evidence, best first
    refined: tuple = field(default=(), repr=False, compare=False)
    contradicted: int = 0  # candidate poses left out on evidence from outside the maps
    # refused only because the maps fit elsewhere too (rivals, symmetric images): the
    # maps agree at the pose, and sightings may yet tell it from the others
    ambiguous: bool = False
    # refused only for conflicts up to PROPOSE_CONFLICT_SHARE (a map bent by drift)
    slight_conflict: bool = False

    @property
    def proposed(self) -> bool:
        """Worth confirming by sightings: accepted, or refused only on what sightings
        settle (ambiguity, slight conflicts). ``FrameEstimate`` commits only such poses."""
        return self.accepted or self.ambiguous or self.slight_conflict

    def summary(self) -> str:
        x, y, th = self.pose
        n = self.contradicted
        seen = f", {n} pose(s) contradicted by sightings" if n else ""
        return (
            f"pose ({x:.2f} m, {y:.2f} m, {math.degrees(th):.1f} deg), overlap "
            f"{self.overlap_m2:.1f} m2, agreeing wall {self.agreeing_wall_m:.1f} m "
            f"({self.agreeing_share:.0%}), conflicts {self.conflict_share:.1%}, rival "
            f"{self.rival_ratio:.2f}, margin {self.margin_wall_m:.1f} m"
            + seen
            + ("" if self.accepted else f": {self.reason}")
        )


# -- the maps as rasters and points ------------------------------------------------------


@dataclass
class _MapView:
    """What the search and the checks need of one map."""

    walls: np.ndarray  # (n, 2) wall points every WALL_STEP_M
    starts: np.ndarray  # obstacle vectors
    ends: np.ndarray
    region: shapely.Geometry  # explored space
    lo: np.ndarray  # raster origin (m)
    hit: np.ndarray  # Gaussian of the distance to a wall, on the raster
    clear: np.ndarray  # 1 where explored, deeper inside than CLEAR_M, and not trodden
    dist: np.ndarray  # distance to the nearest wall (m), on the raster
    normals: np.ndarray  # (n, 2) unit normal of the vector each wall point lies on
    deep: np.ndarray  # True where explored, deeper inside than CLEAR_M (trodden or not)
    trodden: np.ndarray  # True within TRODDEN_M of where the map's robots went
    chain: np.ndarray  # (n,) the wall (obstacle vectors joined end to start) of each point


@dataclass(frozen=True)
class Walls:
    """Wall points every ``WALL_STEP_M`` along obstacle vectors, and the unit normal of
    the vector each lies on (towards the free space: its left)."""

    walls: np.ndarray  # (n, 2)
    normals: np.ndarray  # (n, 2)
    owner: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # vector


def wall_points(starts: np.ndarray, ends: np.ndarray) -> Walls:
    if len(starts) == 0:
        return Walls(np.zeros((0, 2)), np.zeros((0, 2)))
    walls, owner = sample_vectors(starts, ends, WALL_STEP_M)
    d = ends[owner] - starts[owner]
    normals = np.stack([-d[:, 1], d[:, 0]], axis=1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return Walls(walls, normals, owner)


def align_walls(a: Walls, b: Walls, pose, tree: cKDTree | None = None) -> np.ndarray:
    """The pose that puts B's wall points (in their own frame) on A's walls, by
    point-to-line ICP from ``pose`` (a wall face only matches a face seen from the same
    side); ``pose`` itself if ICP wanders farther than ``ICP_MAX_SHIFT_M``. ``tree``:
    A's ``wall_tree``, if the caller has it."""
    return _icp(a, tree if tree is not None else wall_tree(a), b, np.array(pose, dtype=float))


def _view(pmap: GridPolyMap, paths=()) -> _MapView:
    """The map's rasters for the search and the verification. ``paths``: where its robots
    went (polylines, (n, 2) each, in its frame): space within ``TRODDEN_M`` of them is not
    clear (a wall the other map has there may be one of them)."""
    s, e, _ = pmap.vectors([VectorType.OBSTACLE])
    if len(s) == 0:
        raise MatchError("the map has no walls to match")
    w = wall_points(s, e)
    walls, normals = w.walls, w.normals
    region = pmap.explored_region()
    x0, y0, x1, y1 = region.bounds
    lo = np.array([x0, y0]) - 1.0
    shape = (np.ceil((np.array([x1, y1]) + 1.0 - lo) / RESOLUTION_M)).astype(int) + 1
    wall_px = np.ones(shape, dtype=bool)
    ij = np.floor((walls - lo) / RESOLUTION_M).astype(int)
    wall_px[ij[:, 0], ij[:, 1]] = False
    dist = distance_transform_edt(wall_px) * RESOLUTION_M
    hit = np.exp(-0.5 * (dist / HIT_SIGMA_M) ** 2)
    # clear: deeper than CLEAR_M inside the explored space (from walls and frontiers alike:
    # space seen only up to a frontier may end short of a wall the other robot saw)
    deep = _deeper_than(region, CLEAR_M, _rasterise(pmap, lo, shape), lo)
    trodden = _trodden(paths, lo, shape)
    clear = (deep & ~trodden).astype(float)
    chain = _chains(s, e)[w.owner]
    return _MapView(walls, s, e, region, lo, hit, clear, dist, normals, deep, trodden, chain)


def _deeper_than(region, depth_m: float, explored: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """The raster cells (of those ``explored`` marks) whose centres lie deeper than
    ``depth_m`` inside ``region``, measured on the polygons. (Measured on the raster, a
    wall seen 0.1 m inside the other map's walls counted as in its clear space: a drawn
    polygon covers every cell its outline touches, and cell centres are up to a diagonal
    off. The TurtleBot3 office at unknown starts, seed 0: 2-3 % of the walls at the true
    frames, 0.0 % on the polygons.)"""
    inner = shapely.buffer(region, -depth_m)
    ij = np.argwhere(explored)
    centres = (ij + 0.5) * RESOLUTION_M + lo
    out = np.zeros(explored.shape, dtype=bool)
    out[ij[:, 0], ij[:, 1]] = shapely.contains_xy(inner, centres[:, 0], centres[:, 1])
    return out


def _chains(starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Which wall each vector belongs to: vectors are joined where one ends within 1 mm
    of where another starts (across cell borders too)."""
    n = len(starts)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    d, j = cKDTree(starts).query(ends, distance_upper_bound=1e-3)
    ok = np.isfinite(d)
    link = coo_matrix((np.ones(int(ok.sum())), (np.flatnonzero(ok), j[ok])), shape=(n, n))
    return connected_components(link, directed=False)[1]


def _spared(chain: np.ndarray, in_band: np.ndarray) -> np.ndarray:
    """The wall points whose whole wall lies in the other map's trodden band: a robot's
    body seen where it stood (a wall that reaches out of the band is the building's)."""
    if len(chain) == 0:
        return np.zeros(0, dtype=bool)
    outside = np.bincount(chain, weights=~in_band, minlength=int(chain.max()) + 1)
    return outside[chain] == 0


def _trodden(paths, lo: np.ndarray, shape) -> np.ndarray:
    """The raster's cells within ``TRODDEN_M`` of the polylines ``paths``."""
    lines = [np.asarray(p, dtype=float).reshape(-1, 2) for p in paths]
    lines = [p for p in lines if len(p)]
    if not lines:
        return np.zeros(shape, dtype=bool)
    pts = [sample_vectors(p[:-1], p[1:], 0.5 * RESOLUTION_M)[0] if len(p) > 1 else p for p in lines]
    ij = np.floor((np.vstack(pts) - lo) / RESOLUTION_M).astype(int)
    ij = ij[(ij >= 0).all(axis=1) & (ij < shape).all(axis=1)]
    away = np.ones(shape, dtype=bool)
    away[ij[:, 0], ij[:, 1]] = False
    # both the path and a wall point are rounded to a cell: up to a cell's diagonal apart
    return distance_transform_edt(away) * RESOLUTION_M <= TRODDEN_M + math.sqrt(2) * RESOLUTION_M


def _rasterise(pmap: GridPolyMap, lo: np.ndarray, shape) -> np.ndarray:
    """Explored space on the raster (x index first)."""
    img = Image.new("1", (int(shape[0]), int(shape[1])), 0)  # width = x, height = y
    draw = ImageDraw.Draw(img)
    polys = sorted(pmap.dissolve(0.01), key=lambda p: -abs(p.shell.signed_area))
    for p in polys:  # larger shells first: an island in another's hole is drawn after it
        for k, ring in enumerate(p.rings()):
            px = [tuple(v) for v in ((ring.xy - lo) / RESOLUTION_M).tolist()]
            if len(px) >= 3:
                draw.polygon(px, fill=1 if k == 0 else 0)
    return np.asarray(img, dtype=bool).T


# -- refine and verify -------------------------------------------------------------------


def wall_tree(v: _MapView | Walls) -> cKDTree:
    """A's wall points with their normals (scaled): a point matches a wall face seen
    from the same side only (the two faces of a thin wall are apart in normal space)."""
    return cKDTree(np.hstack([v.walls, NORMAL_WEIGHT_M * v.normals]))


def _icp(a: _MapView | Walls, tree: cKDTree, b: _MapView | Walls, pose: np.ndarray) -> np.ndarray:
    """Point-to-line ICP of B's wall points (own frame) on A's walls, the outlier
    cut-off shrinking over the first two thirds of the iterations."""
    start, pose = pose.copy(), pose.copy()
    hold = 2 * ICP_ITERATIONS // 3
    for k in range(ICP_ITERATIONS):
        f = min(k / hold, 1.0)
        cut = ICP_OUTLIER_M[0] + (ICP_OUTLIER_M[1] - ICP_OUTLIER_M[0]) * f
        q = transform_points(pose, b.walls)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        nq = b.normals @ np.array([[c, s], [-s, c]])  # rotated normals
        d, j = tree.query(np.hstack([q, NORMAL_WEIGHT_M * nq]), distance_upper_bound=cut)
        ok = np.isfinite(d)
        if ok.sum() < 10:
            break
        n, r0 = a.normals[j[ok]], q[ok] - a.walls[j[ok]]
        res = np.einsum("ij,ij->i", r0, n)
        # d(q)/d(theta) = perpendicular of (q - t)
        dq = np.stack([-(q[ok, 1] - pose[1]), q[ok, 0] - pose[0]], axis=1)
        J = np.stack([n[:, 0], n[:, 1], np.einsum("ij,ij->i", dq, n)], axis=1)
        step = np.linalg.lstsq(J, -res, rcond=None)[0]
        pose[:2] += step[:2]
        pose[2] = wrap(pose[2] + step[2])  # about the current translation, as dq above
        if np.hypot(*(pose[:2] - start[:2])) > ICP_MAX_SHIFT_M:  # diverged: the search's
            return start  # pose is kept, and verified as it is
        if k >= hold and np.abs(step).max() < 1e-5:
            break
    return pose


def _lookup(v: _MapView, grid: np.ndarray, xy: np.ndarray, outside: float) -> np.ndarray:
    ij = np.floor((xy - v.lo) / RESOLUTION_M).astype(int)
    ok = (ij >= 0).all(axis=1) & (ij < grid.shape).all(axis=1)
    out = np.full(len(xy), outside, dtype=float)
    out[ok] = grid[ij[ok, 0], ij[ok, 1]]
    return out


def _evidence(a: _MapView, b: _MapView, pose: np.ndarray) -> dict:
    """Overlap, agreeing wall and conflicts of B placed at ``pose`` in A."""
    b_in_a = shapely.affinity.affine_transform(
        b.region,
        [
            math.cos(pose[2]),
            -math.sin(pose[2]),
            math.sin(pose[2]),
            math.cos(pose[2]),
            pose[0],
            pose[1],
        ],
    )
    shared = shapely.intersection(a.region, b_in_a)
    near = shapely.buffer(shared, CLEAR_M)
    bw = transform_points(pose, b.walls)
    aw = transform_points(inverse(pose), a.walls)  # A's walls in B's frame
    bw_in = shapely.contains_xy(near, bw[:, 0], bw[:, 1])
    aw_in = shapely.contains_xy(near, a.walls[:, 0], a.walls[:, 1])
    agree_b = _lookup(a, a.dist, bw[bw_in], np.inf) <= INLIER_M
    agree_a = _lookup(b, b.dist, aw[aw_in], np.inf) <= INLIER_M
    # a wall standing wholly where the other map's robots went may be one of them
    spared_b = _spared(b.chain, _lookup(a, a.trodden, bw, 0.0) > 0)
    spared_a = _spared(a.chain, _lookup(b, b.trodden, aw, 0.0) > 0)
    conflict_b = (_lookup(a, a.deep, bw, 0.0) > 0) & ~spared_b
    conflict_a = (_lookup(b, b.deep, aw, 0.0) > 0) & ~spared_a
    inside = max(int(bw_in.sum() + aw_in.sum()), 1)
    conflicts = int(conflict_b.sum() + conflict_a.sum())
    agreeing = int(agree_b.sum() + agree_a.sum())
    return {
        "overlap_m2": float(shared.area),
        "agreeing_wall_m": 0.5 * agreeing * WALL_STEP_M,
        "agreeing_share": agreeing / inside,
        "conflict_share": conflicts / inside,
        "walls_inside": inside,  # wall points of both maps in the shared space (and 0.3 m on)
        # the score the verification ranks by: agreement less conflicts
        "score": float(agreeing - VERIFY_CONFLICT_WEIGHT * conflicts),
    }


def fit_at(maps: list[GridPolyMap], b: GridPolyMap, pose, paths=(), b_paths=()) -> list[dict]:
    """How map B placed at ``pose`` (B's frame in theirs) fits each of ``maps``, as a
    match verifies it: ``overlap_m2``, ``agreeing_wall_m``, ``agreeing_share``,
    ``conflict_share`` (of the wall points near the shared space, ``walls_inside``,
    those standing in the other map's clear space). B is rasterised once. ``paths``
    (in the frame of ``maps``) and ``b_paths``: where the robots went (``_view``)."""
    vb, pose = _view(b, b_paths), np.asarray(pose, dtype=float)
    return [_evidence(_view(a, paths), vb, pose) for a in maps]


def _inconsistency(ev: dict) -> str:
    """Why the maps do not fit at this pose ("" if they do)."""
    if ev["overlap_m2"] < MIN_OVERLAP_M2:
        return f"overlap {ev['overlap_m2']:.1f} m2 < {MIN_OVERLAP_M2} m2"
    if ev["agreeing_wall_m"] < MIN_AGREEING_WALL_M:
        return f"agreeing wall {ev['agreeing_wall_m']:.1f} m < {MIN_AGREEING_WALL_M} m"
    if ev["agreeing_share"] < MIN_AGREEING_SHARE:
        return f"only {ev['agreeing_share']:.0%} of the shared walls agree"
    if ev["conflict_share"] > MAX_CONFLICT_SHARE:
        return f"{ev['conflict_share']:.1%} of the walls stand in the other's clear space"
    return ""


def _verdict(ev: dict, rival: float, margin_m: float, others_fit: int) -> str:
    why = _inconsistency(ev)
    if why:
        return why
    if others_fit:  # a symmetric world: the maps fit elsewhere too, just overlap less
        return f"ambiguous: the maps also fit without contradiction at {others_fit} other pose(s)"
    if rival > MAX_RIVAL_RATIO:
        return f"ambiguous: another pose scores {rival:.0%} of the best"
    if margin_m < MIN_MARGIN_WALL_M:
        return f"ambiguous: another pose explains all but {margin_m:.1f} m of the wall"
    return ""


def match_maps(
    a: GridPolyMap,
    b: GridPolyMap,
    contradicts: Callable[[np.ndarray], bool] | None = None,
    images: bool = True,
    search: Callable = coarse_to_fine,
    a_paths=(),
    b_paths=(),
) -> MapMatch:
    """The pose of map B's frame in map A's frame, with its evidence (see the module).

    ``contradicts``: evidence from outside the maps (``polyswarm.frames.sighting``: the pose
    puts one robot where the other's lidar saw nothing). Candidate poses it contradicts,
    before or after refinement, are left out: in a symmetric building the maps fit the
    truth and its rotated images alike, and the truth stands alone only once the images
    are ruled out. A pose no evidence speaks against stays a rival: nothing is accepted
    on silence.

    ``images``: check an accepted pose against its images under the maps' symmetries
    (two more searches: a match takes about three times as long); an image nothing rules
    out makes the match ambiguous. ``FrameEstimate`` does not need it: the sightings it
    commits on rule out images as well.

    ``search``: ``polyswarm.frames.mapsearch.search``, or ``search_fine`` (the one-pass search
    it is checked against, 3-10 times slower).

    ``a_paths``, ``b_paths``: where each map's robots went (polylines in its frame,
    ``polyswarm.frames.sighting.Track.paths``): a wall of one map there is no conflict with the
    other (``TRODDEN_M``)."""
    va, vb = _view(a, a_paths), _view(b, b_paths)
    cands = search(va, vb)
    if not cands:
        return MapMatch(np.zeros(3), False, "no candidate pose", 0, 0, 0, 1, 0, 0)
    tree = wall_tree(va)
    refined, contradicted = [], 0
    for k, (_, pose) in enumerate(cands):
        # the best PEAKS peaks (not further: a weak peak is no candidate for its rivals),
        # and past them only while the sightings contradicted every one: on the loop at
        # unknown starts, seed 2, the top six were all contradicted in 6 of 8 matches
        # (40 s), and nothing was proposed until the true frame came up among them
        if k >= PEAKS and refined:
            break
        if contradicts is not None and contradicts(pose):
            contradicted += 1
            continue
        p = _icp(va, tree, vb, pose)
        if contradicts is not None and contradicts(p):
            contradicted += 1
            continue
        refined.append((p, _evidence(va, vb, p)))
    if not refined:
        return MapMatch(
            pose=cands[0][1],
            accepted=False,
            reason="every candidate pose is contradicted by sightings",
            overlap_m2=0.0,
            agreeing_wall_m=0.0,
            agreeing_share=0.0,
            conflict_share=1.0,
            rival_ratio=0.0,
            score=0.0,
            candidates=len(cands),
            contradicted=contradicted,
        )
    refined.sort(key=lambda r: -r[1]["score"])
    m = _decide(refined, len(cands), contradicted)
    if m.accepted and images:
        why = _symmetric_images(va, vb, m.pose, contradicts, search)
        if why:
            return replace(m, accepted=False, reason=why, ambiguous=True)
    return m


def _symmetries(v: _MapView, search=coarse_to_fine) -> list[np.ndarray]:
    """The poses ``S`` (not the identity) at which a map fits itself: ``S`` moves it onto
    itself without contradiction (a ring corridor after a quarter turn, a corridor along
    itself, a row of identical rooms)."""
    tree = wall_tree(v)
    out: list[np.ndarray] = []
    for _, pose in search(v, v)[:PEAKS]:
        if _close(pose, np.zeros(3), RIVAL_APART_M, RIVAL_APART_RAD):
            continue
        p = _icp(v, tree, v, pose)
        moved = not _close(p, np.zeros(3), RIVAL_APART_M, RIVAL_APART_RAD)
        if moved and not _inconsistency(_evidence(v, v, p)):
            out.append(p)
    return out


def _symmetric_images(
    a: _MapView,
    b: _MapView,
    pose: np.ndarray,
    contradicts: Callable[[np.ndarray], bool] | None,
    search=coarse_to_fine,
) -> str:
    """Why ``pose`` cannot be told from an image of it ("" if it can). Where map A fits
    itself at ``S``, B fits A at ``S pose`` as well as at ``pose``; where B fits itself,
    at ``pose S^-1``. Such an image may overlap the other map little yet (the robots have
    seen little of the same place), so no peak of the search shows it; unless the maps
    contradict it (walls in each other's clear space) or sightings do, it may be the
    truth."""
    images = [compose(s, pose) for s in _symmetries(a, search)]
    images += [compose(pose, inverse(s)) for s in _symmetries(b, search)]
    for img in images:
        if _close(img, pose, RIVAL_APART_M, RIVAL_APART_RAD):
            continue
        if _evidence(a, b, img)["conflict_share"] > MAX_CONFLICT_SHARE:
            continue  # the maps rule it out
        if contradicts is not None and contradicts(img):
            continue  # sightings rule it out
        x, y, th = img
        return (
            "ambiguous: the maps are symmetric and nothing rules out their image at "
            f"({x:.2f} m, {y:.2f} m, {math.degrees(th):.1f} deg)"
        )
    return ""


def _decide(refined: list, candidates: int, contradicted: int = 0) -> MapMatch:
    """The verdict on the best of the ``refined`` poses (best first), the others its
    rivals."""
    best, ev = refined[0]
    others = [r for r in refined[1:] if not _close(r[0], best, RIVAL_APART_M, RIVAL_APART_RAD)]
    rival_score = max((r[1]["score"] for r in others), default=0.0)
    rival = rival_score / max(ev["score"], 1e-9)
    margin_m = 0.5 * WALL_STEP_M * (ev["score"] - max(rival_score, 0.0))  # as agreeing wall
    others_fit = sum(not _inconsistency(r[1]) for r in others)
    reason = _verdict(ev, rival, margin_m, others_fit)
    slight = (
        ev["conflict_share"] <= PROPOSE_CONFLICT_SHARE
        and _inconsistency({**ev, "conflict_share": 0.0}) == ""
    )
    return MapMatch(
        best,
        reason == "",
        reason,
        ambiguous=reason.startswith("ambiguous"),
        slight_conflict=reason != "" and not reason.startswith("ambiguous") and slight,
        rival_ratio=rival,
        candidates=candidates,
        margin_wall_m=margin_m,
        refined=tuple(refined),
        contradicted=contradicted,
        **{k: v for k, v in ev.items() if k != "walls_inside"},
    )


def fitting_rivals(m: MapMatch) -> list[np.ndarray]:
    """The other refined poses of ``m`` where the maps fit as well, without contradiction
    (apart from ``m.pose``): in a symmetric building, the images of the truth (or the
    truth, when an image scored best)."""
    return [
        pose
        for pose, ev in m.refined
        if not _close(pose, m.pose, RIVAL_APART_M, RIVAL_APART_RAD) and not _inconsistency(ev)
    ]


def verdict_at(m: MapMatch, pose: np.ndarray) -> MapMatch:
    """``m``'s verdict on another of its refined poses (one ``fitting_rivals`` gave),
    ``m.pose`` among its rivals."""
    chosen = [r for r in m.refined if r[0] is pose]
    if not chosen:
        raise ValueError("verdict_at: the pose is not one of the match's refined poses")
    rest = [r for r in m.refined if r[0] is not pose]
    return _decide(chosen + rest, m.candidates, m.contradicted)


def transform_map(pmap: GridPolyMap, pose) -> GridPolyMap:
    """The map moved by ``pose`` (x m, y m, theta rad): cut into cells again, version 0."""
    polys = []
    for p in pmap.dissolve():
        rings = [Ring(transform_points(pose, r.xy), r.types) for r in p.rings()]
        polys.append(TypedPolygon(rings[0], tuple(rings[1:])))
    return GridPolyMap.from_polygons(polys, pmap.cell_size)


def frame_error(est, truth) -> tuple[float, float]:
    """(metres, radians) between two poses of a frame."""
    d = compose(inverse(np.asarray(truth, float)), np.asarray(est, float))
    return float(np.hypot(d[0], d[1])), float(abs(wrap(d[2])))
