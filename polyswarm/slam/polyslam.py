"""PolySLAM: the per-scan step, one line per stage of the thesis' figure 3.4.

    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=(0, 0, 0))
    step = slam.process(scan, odom_pose)
    step.pose                  # (x, y, theta) estimate in the map frame
    step.delta                 # on keyframes: the map cells that changed
    step.op                    # ...and the merge that changed them (polymap.MergeOp)
    step.correction            # ...after a loop closure moved keyframes (follow.CorrectionOp)
    slam.map                   # the robot's GridPolyMap

Only keyframes (moved ``keyframe_distance_m`` or turned ``keyframe_angle_rad`` since
the last one) are aligned and merged; other scans get the odometry prediction.

Beyond the thesis: ICP matches against the obstacle vectors of the nearby keyframes
rather than the merged map (``polyswarm.slam.submap`` says why), and each keyframe is a node
of a pose graph whose loop edges (a scan matched against an old part of the map) are
optimised as they are found (``polyswarm.slam.posegraph``). With ``slam.map_follows_graph``
the map follows each correction (``polyswarm.slam.follow``): the cells of the keyframes it
moved are merged again; otherwise a correction moves the robot and the keyframes it
matches against, not what it already merged. ``rebuild_map()`` merges every keyframe
afresh at its optimised pose (offline runs), and ``trajectory()`` gives every scan's
optimised pose.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from polyswarm.config import IcpReference, SlamConfig
from polyswarm.errors import PolyswarmError
from polyswarm.frames.mapmatch import transform_map
from polyswarm.polymap import (
    UNITS_PER_M,
    GridPolyMap,
    MapDelta,
    MergeOp,
    MergeOptions,
    VectorType,
    cells_digest,
    snap_polygon,
)
from polyswarm.se2 import compose, inverse, relative, transform_points, wrap
from polyswarm.slam import gridmatch
from polyswarm.slam.evidence import EvidenceGrid, KeyframeRays, view_points
from polyswarm.slam.follow import Atlas, CorrectionOp, pose_of
from polyswarm.slam.icp import IcpResult, PointToVectorIcp
from polyswarm.slam.keyframe import KeyframeSelector, keyframe_polygon
from polyswarm.slam.loops import LoopClosing, rotate
from polyswarm.slam.loopsearch import correlative_search
from polyswarm.slam.odomscale import OdometryScale
from polyswarm.slam.posegraph import PoseGraph
from polyswarm.slam.refine import refine_polygon
from polyswarm.slam.scan import LaserScan, isolated_blobs, scan_to_points
from polyswarm.slam.submap import KeyframeStore
from polyswarm.slam.trim import trim_keyframe

log = logging.getLogger(__name__)

# odometry and de-skewing to the nanometre and nanoradian: the same recording through
# any transport (a quaternion, float stamps) maps the same (ICP and the evidence match
# are not continuous in their input's last bits)
INPUT_DECIMALS = 9
ODOMETRY_SIGMA_PER_M = 0.1  # std of odometry along a corridor, per metre travelled
# a scan that sees new space (slam.keyframe_novelty) is a keyframe once the robot has
# moved this share of the way to the next one...
NOVELTY_MIN_STEP = 0.25
# ... judged by its beams' ends pulled back this far towards the sensor (a wall already
# mapped lies on the explored space's edge, its noisy returns on either side of it)
NOVELTY_PULL_M = 0.2


@dataclass(frozen=True)
class SlamStep:
    pose: np.ndarray
    keyframe: bool
    delta: MapDelta | None = None
    op: MergeOp | None = None  # the same change as the merge that made it
    # a loop closure moved keyframes before the merge: the delta covers both, sent as this
    # correction then ``op`` (its base is the correction's version)
    correction: CorrectionOp | None = None
    icp: IcpResult | None = None
    refined: str = ""  # "refined", "projected" or "raw" on keyframes
    timings_ms: dict[str, float] = field(default_factory=dict)
    anchored: bool = False  # this step moved the SLAM into the frame ``anchor`` gave


# ICP from outside its basin (csail's wheel odometry is 15-30 deg off over fast turns) is
# seeded again by a correlative search around the prediction (csail ATE 6.49 -> 0.10 m)
POOR_FIT_SHARE = 0.3  # ICP matched fewer than this share of the scan's points
RESEED_WINDOW_M = 0.5  # the search window around the prediction: +-0.5 m ...
RESEED_WINDOW_RAD = math.radians(30.0)  # ... and +-30 degrees, in 5 cm and 1 degree steps
RESEED_GAIN = 1.25  # the second fit is kept if it matches this many times the points
# the pose refined on the evidence's walls is kept unless fewer returns end on a wall
# there than at ICP's pose (pose error p95 over 4 profiles: 0.94 m without, 0.505 m with)
GRID_MARGIN = 0.0


class PolySlam(LoopClosing):
    def __init__(
        self,
        cfg: SlamConfig,
        cell_size_m: float = 2.0,
        initial_pose=(0.0, 0.0, 0.0),
        keep_trajectory: bool = False,
        out_of_range: str = "inf",
    ) -> None:
        """``keep_trajectory``: remember every scan for ``trajectory()`` (offline runs; a
        long-running agent leaves it off so its memory does not grow with every scan).
        ``out_of_range``: how the lidar's driver reports a beam with no return
        (``polyswarm.config.OutOfRange``)."""
        self.cfg = cfg
        self.reseeded = 0  # keyframes whose ICP was seeded again by a correlative search
        self.grid_refined = 0  # keyframes whose ICP pose was refined on the evidence
        self.out_of_range = out_of_range
        self.map = GridPolyMap(cell_size_m)
        self.pose = np.array(initial_pose, dtype=float)
        self.odom: np.ndarray | None = None  # the odometry reading that goes with self.pose
        self.icp = PointToVectorIcp(cfg.icp)
        self.selector = KeyframeSelector(cfg.keyframe_distance_m, cfg.keyframe_angle_rad)
        self._kf_pose: np.ndarray | None = None  # map-frame pose at the last keyframe
        self._kf_odom: np.ndarray | None = None
        self._kf_pinned = False  # ICP pinned the last keyframe down in every direction
        self.odometry_scale = OdometryScale()  # the odometry's distance scale, learnt
        self.merge_options = MergeOptions(
            cfg.min_growth_m,
            cfg.obstacle_snap_m,
            cfg.notch_fill_m,
            cfg.obstacle_snap_behind_m,
            cfg.obstacle_snap_front_m,
        ).on_grid()  # whole 10 um units: a receiver of a MergeOp gets the same floats
        self._quantum_u = round(cfg.merge_quantum_m * UNITS_PER_M)  # 10 um units, 0: off
        self.keyframes = 0
        self.degenerate_keyframes = 0
        self.rejected_keyframes = 0
        self.blob_returns_skipped = 0  # returns left out of ICP as blobs (``process``)
        self._keyframe_requested = False
        sub = cfg.submap
        self.store = KeyframeStore(sub.keyframes, sub.radius_m, sub.recent)
        self.graph = PoseGraph()
        self.keep_trajectory = keep_trajectory
        self._steps: list[tuple[int, np.ndarray]] = []  # every scan: (keyframe, offset)
        self._last_loop = self._last_search = -(10**9)  # keyframes of the last loop, search
        self._travel_since_loop_m = 0.0  # distance driven since the last loop edge
        # the map follows the pose graph (polyswarm.slam.follow): the keyframes as merged and
        # where they are placed now, this step's correction, and what each one cost
        self.atlas = Atlas()
        self._frames: dict[int, np.ndarray] = {}  # keyframe -> its atlas frame, seen from it
        self._follows = cfg.map_follows_graph
        # the evidence behind the map: every scan's rays, kept per keyframe (None: off)
        self.evidence: KeyframeRays | None = None
        if cfg.evidence.enabled:
            self.evidence = KeyframeRays(EvidenceGrid(cfg.evidence.resolution_m))
        self._correction: CorrectionOp | None = None
        self.corrections: list[dict] = []
        self._anchor: np.ndarray | None = None  # a frame to move into at the next scan
        self._anchor_base: int | None = None  # the map's version before that move
        self.anchors = 0  # frames moved into
        # priors from the swarm's joint pose graph, applied at the next keyframe
        self._priors: dict[int, np.ndarray] | None = None
        self._prior_sigmas = (0.05, 0.01)  # metres, radians: replaced with the priors
        self._optimise = False  # priors set: the graph is optimised in this keyframe step
        self.priors_applied = 0

    def resume(
        self, pmap: GridPolyMap, pose, odom=None, scale: OdometryScale | None = None
    ) -> None:
        """Continue on a persisted map from the last known pose (an agent restarted): the
        next scan is a keyframe aligned against that map. ``odom`` is the odometry reading
        at ``pose``: the robot base counts on while the agent is down, so the robot's motion
        since is predicted from it. Without it the robot is taken to stand at ``pose``.
        ``scale``: the odometry's distance scale learnt before (else it is learnt again)."""
        if abs(pmap.cell_size - self.map.cell_size) > 1e-9:
            raise PolyswarmError(
                f"persisted map has {pmap.cell_size} m cells, the config {self.map.cell_size} m"
            )
        self.map = pmap
        self.pose = np.array(pose, dtype=float)
        if scale is not None:
            self.odometry_scale = scale
        sub = self.cfg.submap  # the keyframes are not persisted: match the map until new ones
        self.store = KeyframeStore(sub.keyframes, sub.radius_m, sub.recent)
        # the map holds keyframes the store does not: rebuilding cells from the store
        # alone would drop them, so a resumed map no longer follows the graph
        self.atlas = Atlas()
        self._frames = {}
        self._follows = False
        if self.evidence is not None:  # the scans behind the persisted map are gone
            self.evidence = KeyframeRays(EvidenceGrid(self.cfg.evidence.resolution_m))
        self.graph = PoseGraph()
        self._steps = []
        self._kf_pose = self._kf_odom = None
        self._kf_pinned = False
        if odom is not None:
            self._kf_pose, self._kf_odom = self.pose.copy(), np.array(odom, dtype=float)
        self.odom = self._kf_odom
        self.selector.last = None
        self._keyframe_requested = True

    def anchor(self, frame) -> None:
        """Move into another frame at the next scan: ``frame`` (x m, y m, theta rad) is
        where this SLAM's frame lies in it (the shared map frame, found by the
        coordinator: ``agents.anchoring``). The pose graph, the keyframes and the pose
        move by it; the map follows as a correction of every keyframe (a resumed map,
        which does not follow the graph, as all its cells), sent with that scan, which
        is made a keyframe."""
        self._anchor = np.array(frame, dtype=float)

    def _apply_anchor(self) -> None:
        frame, self._anchor = self._anchor, None
        self._anchor_base = self.map.version
        self.graph.move_all(frame)
        if self.evidence is not None:
            self.evidence.move_to(self.graph.poses)
        if self.store:
            self.store.set_poses(np.array([compose(frame, k.pose) for k in self.store.keyframes]))
        self.pose = compose(frame, self.pose)
        if self._kf_pose is not None:
            self._kf_pose = compose(frame, self._kf_pose)
        self._keyframe_requested = True
        self.anchors += 1
        if self._follows:
            self._follow()
            return
        moved = transform_map(self.map, frame)
        self.map, _ = self.map.with_cells_of(moved, set(self.map.cells) | set(moved.cells))

    def constrain(self, frames: dict[int, np.ndarray], sigma_m: float, sigma_rad: float) -> int:
        """Priors from the swarm's joint pose graph (``polyswarm.frames.jointgraph``): keyframe id
        -> where the frame its polygon is held at (``polyswarm.slam.follow``) belongs, in the
        frame this SLAM is in. They replace earlier priors in the pose graph, which is
        optimised at the next scan (made a keyframe); the map follows as after a loop
        closure. Keyframes not held (a resumed map does not follow the graph) are left
        out; the priors taken are counted."""
        if not self._follows:
            return 0
        n = len(self.graph)
        poses = {
            kid: compose(np.asarray(p, dtype=float), inverse(self._frames[kid]))
            for kid, p in frames.items()
            if kid in self._frames and kid < n
        }
        if poses:
            self._priors = poses
            self._prior_sigmas = (sigma_m, sigma_rad)
            self._keyframe_requested = True
        return len(poses)

    def clear_priors(self) -> None:
        """Forget the joint pose graph's priors (the frame they were given in was
        withdrawn); the graph keeps the poses they gave."""
        self._priors = None
        self.graph.priors = {}

    def request_keyframe(self) -> None:
        """Make the next scan a keyframe (a robot that stopped to look at something)."""
        self._keyframe_requested = True

    def process(
        self, scan: LaserScan, odom, motion: np.ndarray | None = None, blobs_m: float = 0.0
    ) -> SlamStep:
        """One scan with the odometry pose of the time its points are expressed at;
        ``motion`` (``polyswarm.slam.scan.deskew_motion``) de-skews a rolling sweep.
        ``blobs_m`` > 0: returns in isolated blobs no wider than that (metres;
        ``polyswarm.slam.scan.isolated_blobs``) are left out of ICP and loop closure, still
        mapped: other robots the caller cannot place, which would pull the pose along
        a corridor as they move."""
        odom = np.round(np.array(odom, dtype=float), INPUT_DECIMALS)
        if not np.isfinite(odom).all():
            raise PolyswarmError(f"odometry pose is not finite: {odom}")
        if motion is not None:
            motion = np.round(np.asarray(motion, dtype=float), INPUT_DECIMALS)
        if self._anchor is not None:
            self._apply_anchor()
        # 3. pre-alignment: last keyframe pose plus the odometry increment since then
        pred = (
            self.pose
            if self._kf_pose is None
            else compose(self._kf_pose, self._odometry_step(odom))
        )
        t = {"start": time.perf_counter()}
        # 1. scan to points (robot frame, de-skewed; invalid beams become free space,
        #    short frontier points, or are left out)
        points = self._points(scan, motion)
        t["points"] = time.perf_counter()
        # 2. keyframe selection: enough travel or rotation, or a view of new space
        if not self._keyframe_due(odom, points, pred):
            return self._track(pred, odom, points)
        start_version = self.map.version
        anchor_base, self._anchor_base = self._anchor_base, None
        if anchor_base is not None:  # moved into another frame: the delta starts before
            start_version = anchor_base
        # 4. point-to-vector ICP against the obstacle vectors near the robot
        res, pose, valid = self._match(points, pred, blobs_m, scan.range_max)
        pinned = self._learn_scale(res, odom, len(valid))
        t["icp"] = time.perf_counter()
        # 4b. pose graph: this keyframe's node, its tracking edge, and a loop edge when
        # the scan also matches an old part of the map
        # (not in the step that moved into another frame: one correction per step)
        pose = self._add_to_graph(pose, res, valid, points.origin, anchor_base is None)
        if self._optimise:  # priors set and no loop closure optimised the graph
            pose = self._optimise_graph()
        t["loop"] = time.perf_counter()
        # 5. keyframe polygon, closed through the sensor centre: of the scan's points, or
        #    of the view of every scan's evidence from the keyframe's lidar
        kf = self._keyframe_polygon(scan, points, pose)
        t["polygon"] = time.perf_counter()
        # 6. refinement by line fitting (always a valid simple polygon)
        kf, how = refine_polygon(kf, self.cfg.refine)
        t["refine"] = time.perf_counter()
        # 7. merge into the robot's map, its vertices on the wire's grid; the changed cells
        # are the delta, and the merge itself is a smaller one
        # (after a correction, the delta starts before it)
        correction, self._correction = self._correction, None
        base = self.map.version
        if correction is not None or anchor_base is not None:
            base = start_version
        op = self._merge(kf, pose)
        if anchor_base is not None and correction is None:
            op = None  # a map moved as cells: receivers take the cells, not a replay
        t["merge"] = time.perf_counter()
        delta = self.map.delta_since(base) if self.map.version != base else None
        self._keyframe_done(pose, kf, odom, pinned)
        return SlamStep(
            self.pose.copy(),
            True,
            delta,
            op,
            correction,
            res,
            how,
            _stage_ms(t),
            anchor_base is not None,
        )

    def _points(self, scan: LaserScan, motion):
        m = self.cfg.mount
        return scan_to_points(
            scan,
            self.cfg.frontier_range_m,
            (m.x_m, m.y_m, m.yaw_rad, m.upside_down),
            self.cfg.no_return_free_m,
            self.out_of_range,
            motion,
        )

    def _keyframe_due(self, odom, points, pred) -> bool:
        due = self.selector.due(odom) or self._keyframe_requested
        if not due and self.cfg.keyframe_novelty > 0 and self.map.cells:
            due = self.selector.moved(odom, NOVELTY_MIN_STEP) and self._sees_new_space(points, pred)
        return due

    def _track(self, pred, odom, points) -> SlamStep:
        """A scan that is no keyframe: the pose by odometry, its evidence counted."""
        self.pose, self.odom = pred, odom
        if self.evidence is not None and len(self.graph):  # seen from its keyframe
            node = len(self.graph) - 1
            self.evidence.add(node, self.graph.poses[node], relative(self._kf_pose, pred), points)
        if self.keep_trajectory:  # as seen from its keyframe, to follow corrections
            self._steps.append((len(self.graph) - 1, relative(self._kf_pose, pred)))
        return SlamStep(pred, False)

    def _match(self, points, pred, blobs_m: float, range_m: float):
        """ICP (refined on the evidence) of the keyframe's returns: the result (None
        without a reference), the pose, and the returns it used."""
        res, pose = None, pred
        aligned = points.valid
        if blobs_m > 0:
            blobs = isolated_blobs(points, blobs_m)
            self.blob_returns_skipped += int(blobs.sum())
            aligned = aligned & ~blobs
        valid = points.xy[aligned]
        if len(valid) and (self.store or self.map.cells):
            res = self._align(valid, pred, points.origin)
            if self.evidence is not None and res.inliers > 0:
                res = self._refine_on_evidence(res, valid, range_m)
            pose = res.pose if res.inliers > 0 else pred
            self.degenerate_keyframes += res.degenerate_axis is not None
        return res, pose, valid

    def _keyframe_polygon(self, scan: LaserScan, points, pose):
        seen = points
        if self.evidence is not None:
            node = len(self.graph) - 1
            self.evidence.add(node, pose, np.zeros(3), points)
            seen = view_points(
                self.evidence.grid,
                points,
                pose,
                scan.fov,
                len(scan.ranges),
                scan.range_max,
                self.cfg.frontier_range_m,
                self.cfg.evidence.oversample,
            )
        return keyframe_polygon(
            seen, pose, self.cfg.obstacle_max_gap_m, self.cfg.obstacle_gap_beams
        )

    def _merge(self, kf, pose) -> MergeOp | None:
        """The keyframe merged into the map (trimmed, snapped); the merge as a replayable
        operation, or None. A keyframe that fails to merge is counted and logged, never
        skipped silently; its pose is still tracked."""
        news = trim_keyframe(kf, self.map, self.merge_options) if self.cfg.trim_merges else kf
        snapped = snap_polygon(news, self._quantum_u) if self._quantum_u else None
        op = None
        try:
            before = self.map.version
            merged = self.map.merge(news if snapped is None else snapped, self.merge_options)
            self.map = merged.map
            if snapped is not None and merged.changed:
                digest = cells_digest(merged.map.cells[i] for i in merged.changed)
                kid = len(self.store) if self._follows else None
                op = MergeOp(
                    self.map.cell_size,
                    before,
                    self.map.version,
                    snapped,
                    self.merge_options,
                    digest,
                    kid,
                )
                if kid is not None:  # what every receiver's atlas holds after replaying op
                    self.atlas.add(kid, snapped, self.merge_options)
                    # the atlas holds it at a frame of its own: seen from the keyframe
                    self._frames[kid] = relative(pose, pose_of(self.atlas.poses[kid]))
        except PolyswarmError as e:
            self.rejected_keyframes += 1
            log.warning("keyframe %d not merged: %s", self.keyframes, e)
        return op

    def _keyframe_done(self, pose, kf, odom, pinned: bool) -> None:
        self.store.add(pose, kf)
        if self.keep_trajectory:
            self._steps.append((len(self.graph) - 1, np.zeros(3)))
        self.pose = np.array([pose[0], pose[1], float(wrap(pose[2]))])
        self._kf_pose, self._kf_odom = self.pose.copy(), odom
        self._kf_pinned = pinned
        self.odom = odom
        self.selector.mark(odom)
        self._keyframe_requested = False
        self.keyframes += 1

    def _sees_new_space(self, points, pose) -> bool:
        """Do ``keyframe_novelty`` of the scan's beams end (pulled back by
        ``NOVELTY_PULL_M`` towards the sensor) outside the explored space?"""
        rel = points.xy - points.origin
        d = np.hypot(rel[:, 0], rel[:, 1])
        keep = d > NOVELTY_PULL_M
        if not keep.any():
            return False
        back = points.origin + rel[keep] * (1.0 - NOVELTY_PULL_M / d[keep])[:, None]
        unknown = ~self.map.is_free_many(transform_points(pose, back))
        return bool(unknown.mean() >= self.cfg.keyframe_novelty)

    # -- the odometry's scale -------------------------------------------------------------

    def _odometry_step(self, odom: np.ndarray) -> np.ndarray:
        """The odometry's motion since the last keyframe, its distance scale corrected."""
        step = relative(self._kf_odom, odom)
        return self.odometry_scale.correct(step) if self.cfg.learn_odometry_scale else step

    def _learn_scale(self, res: IcpResult | None, odom: np.ndarray, n_points: int) -> bool:
        """Did ICP pin this keyframe down in every direction? If the last one was pinned
        too, the motion between them is a measure of the odometry's scale."""
        pinned = bool(
            res is not None
            and res.converged
            and res.degenerate_axis is None
            and res.inliers >= POOR_FIT_SHARE * n_points
        )
        if pinned and self._kf_pinned and self._kf_pose is not None:
            self.odometry_scale.add(
                relative(self._kf_odom, odom)[:2], relative(self._kf_pose, res.pose)[:2]
            )
        return pinned

    # -- stage 4's reference and the pose graph ------------------------------------------

    def _align(self, valid: np.ndarray, pred: np.ndarray, origin: np.ndarray) -> IcpResult:
        """ICP from the prediction; after a poor fit (the prediction may lie outside
        ICP's basin: real wheel odometry off by 15-30 degrees over a fast turn), ICP again
        from the best pose of a correlative search around it, kept if it fits better."""
        s, e = self._reference(pred)
        res = self.icp.align(valid, pred, s, e, origin)
        if res.inliers < POOR_FIT_SHARE * len(valid) and len(s):
            guess, _, ambiguous = correlative_search(
                valid, pred, s, e, RESEED_WINDOW_M, 0.05, RESEED_WINDOW_RAD, math.radians(1.0)
            )
            if ambiguous:  # another pose fits nearly as well (a corridor): the prediction
                return res
            again = self.icp.align(valid, guess, s, e, origin)
            if again.inliers > RESEED_GAIN * res.inliers:
                self.reseeded += 1
                return again
        return res

    def _refine_on_evidence(self, res: IcpResult, valid: np.ndarray, range_m: float) -> IcpResult:
        """ICP's pose refined against every wall of the evidence (``slam.gridmatch``), kept
        when clearly more of the returns end on a wall there: ICP against few keyframes
        with few points can settle beside the walls; where it fits well the grid's 5 cm
        cells are less precise than its vectors, so it is kept. In a corridor (a
        degenerate axis) the position along it stays ICP's."""
        out = gridmatch.refine(self.evidence.grid, valid, res.pose, range_m)
        if out is None:
            return res
        pose, share, before = out
        if share < before + GRID_MARGIN:
            return res
        if res.degenerate_axis is not None:
            along = res.degenerate_axis @ (pose[:2] - res.pose[:2])
            pose = np.r_[pose[:2] - along * res.degenerate_axis, pose[2]]
        self.grid_refined += 1
        return replace(res, pose=pose)

    def _reference(self, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.store and self.cfg.submap.reference == IcpReference.KEYFRAMES:
            return self.store.reference(pred)
        s, e, _ = self.map.vectors(
            [VectorType.OBSTACLE],
            self.map.cells_within(pred[0], pred[1], self.cfg.icp.map_radius_m),
        )
        return s, e

    def _add_to_graph(
        self, pose, res: IcpResult | None, valid, origin, loops: bool = True
    ) -> np.ndarray:
        """Add the keyframe to the pose graph; its pose after any loop correction
        (``loops``: look for one)."""
        lc = self.cfg.loop_closure
        node = self.graph.add_node(pose)
        if loops and self._priors is not None:  # not in the step that moved frames
            priors, self._priors = self._priors, None
            self.graph.set_priors(priors, *self._prior_sigmas)
            self._optimise = True
            self.priors_applied += 1
        if node == 0:
            return pose
        prev = self.graph.poses[node - 1]
        z = relative(prev, pose)
        tracked = res is not None and res.inliers > 0
        weak = None  # a corridor: along it the edge is only as good as the odometry
        if tracked and res.degenerate_axis is not None:
            weak = rotate(res.degenerate_axis, -prev[2])
        sigma_rad = lc.odometry_sigma_rad
        if tracked:
            sigma_rad = max(
                lc.tracking_sigma_rad, lc.heading_sigma_inflation * res.heading_sigma_rad
            )
        self.graph.add_edge(
            node - 1,
            node,
            z,
            lc.tracking_sigma_m if tracked else lc.odometry_sigma_m,
            sigma_rad,
            weak_axis=weak,
            weak_sigma_m=lc.odometry_sigma_m + ODOMETRY_SIGMA_PER_M * float(np.hypot(*z[:2])),
        )
        self._travel_since_loop_m += float(np.hypot(*z[:2]))
        if not lc.enabled or not loops or len(valid) == 0:
            return pose
        return self._close_loop(node, pose, valid, origin)

    def trajectory(self) -> np.ndarray:
        """Every processed scan's pose with all pose-graph corrections applied."""
        if not self.keep_trajectory:
            raise PolyswarmError("trajectory() needs PolySlam(..., keep_trajectory=True)")
        kf = self.graph.poses
        return np.array([compose(kf[i], off) for i, off in self._steps]).reshape(-1, 3)


def _stage_ms(t: dict[str, float]) -> dict[str, float]:
    """Milliseconds of each stage (``t``: the clock after each) and in all."""
    names = ["points", "icp", "loop", "polygon", "refine", "merge"]
    prev, ms = t["start"], {}
    for name in names:
        ms[name] = (t[name] - prev) * 1e3
        prev = t[name]
    ms["total"] = (t["merge"] - t["start"]) * 1e3
    return ms
