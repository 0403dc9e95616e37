"""PolySLAM: the per-scan step, one line per stage of the thesis' figure 3.4.

    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=(0, 0, 0))
    step = slam.process(scan, odom_pose)
    step.pose                  # (x, y, theta) estimate in the map frame
    step.delta                 # on keyframes: the map cells that changed
    slam.map                   # the robot's GridPolyMap

Only keyframes (moved ``keyframe_distance_m`` or turned ``keyframe_angle_rad`` since
the last one) are aligned and merged; other scans get the odometry prediction.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from polyswarm.config import SlamConfig
from polyswarm.errors import PolyswarmError
from polyswarm.icp import IcpResult, PointToVectorIcp
from polyswarm.keyframe import keyframe_polygon
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOptions, VectorType
from polyswarm.refine import refine_polygon
from polyswarm.scan import LaserScan, scan_to_points
from polyswarm.se2 import compose, relative, wrap

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SlamStep:
    pose: np.ndarray
    keyframe: bool
    delta: MapDelta | None = None
    icp: IcpResult | None = None
    refined: str = ""  # "refined", "projected" or "raw" on keyframes
    timings_ms: dict[str, float] = field(default_factory=dict)


class KeyframeSelector:
    """Stage 2: a new keyframe after enough travel or rotation (odometry)."""

    def __init__(self, distance_m: float, angle_rad: float) -> None:
        self.distance_m, self.angle_rad = distance_m, angle_rad
        self.last: np.ndarray | None = None

    def due(self, odom: np.ndarray) -> bool:
        if self.last is None:
            return True
        d = relative(self.last, odom)
        return bool(np.hypot(d[0], d[1]) >= self.distance_m or abs(d[2]) >= self.angle_rad)

    def mark(self, odom: np.ndarray) -> None:
        self.last = np.array(odom, dtype=float)


class PolySlam:
    def __init__(
        self, cfg: SlamConfig, cell_size_m: float = 2.0, initial_pose=(0.0, 0.0, 0.0)
    ) -> None:
        self.cfg = cfg
        self.map = GridPolyMap(cell_size_m)
        self.pose = np.array(initial_pose, dtype=float)
        self.icp = PointToVectorIcp(cfg.icp)
        self.selector = KeyframeSelector(cfg.keyframe_distance_m, cfg.keyframe_angle_rad)
        self._kf_pose: np.ndarray | None = None  # map-frame pose at the last keyframe
        self._kf_odom: np.ndarray | None = None
        self.merge_options = MergeOptions(cfg.min_growth_m, cfg.obstacle_snap_m, cfg.notch_fill_m)
        self.keyframes = 0
        self.degenerate_keyframes = 0
        self.rejected_keyframes = 0
        self._keyframe_requested = False

    def resume(self, pmap: GridPolyMap, pose) -> None:
        """Continue on a persisted map from the last known pose (an agent restarted where
        its robot stands): the next scan is a keyframe aligned against that map."""
        if abs(pmap.cell_size - self.map.cell_size) > 1e-9:
            raise PolyswarmError(
                f"persisted map has {pmap.cell_size} m cells, the config {self.map.cell_size} m"
            )
        self.map = pmap
        self.pose = np.array(pose, dtype=float)
        self._kf_pose = self._kf_odom = None
        self.selector.last = None
        self._keyframe_requested = True

    def request_keyframe(self) -> None:
        """Make the next scan a keyframe (a robot that stopped to look at something)."""
        self._keyframe_requested = True

    def process(self, scan: LaserScan, odom) -> SlamStep:
        odom = np.array(odom, dtype=float)
        if not np.isfinite(odom).all():
            raise PolyswarmError(f"odometry pose is not finite: {odom}")
        # 3. pre-alignment: last keyframe pose plus the odometry increment since then
        pred = (
            self.pose
            if self._kf_pose is None
            else compose(self._kf_pose, relative(self._kf_odom, odom))
        )
        # 2. keyframe selection
        if not (self.selector.due(odom) or self._keyframe_requested):
            self.pose = pred
            return SlamStep(pred, False)
        t = {"start": time.perf_counter()}
        m = self.cfg.mount
        # 1. scan to points (robot frame; invalid beams become short frontier points)
        points = scan_to_points(
            scan, self.cfg.frontier_range_m, (m.x_m, m.y_m, m.yaw_rad, m.upside_down)
        )
        t["points"] = time.perf_counter()
        # 4. point-to-vector ICP against the obstacle vectors near the robot
        res = None
        pose = pred
        if self.map.cells and points.valid.sum() > 0:
            s, e, _ = self.map.vectors(
                [VectorType.OBSTACLE],
                self.map.cells_within(pred[0], pred[1], self.cfg.icp.map_radius_m),
            )
            res = self.icp.align(points.xy[points.valid], pred, s, e, points.origin)
            pose = res.pose if res.inliers > 0 else pred
            self.degenerate_keyframes += res.degenerate_axis is not None
        t["icp"] = time.perf_counter()
        # 5. keyframe polygon, closed through the sensor centre
        kf = keyframe_polygon(
            points, pose, self.cfg.obstacle_max_gap_m, self.cfg.obstacle_gap_beams
        )
        t["polygon"] = time.perf_counter()
        # 6. refinement by line fitting (always a valid simple polygon)
        kf, how = refine_polygon(kf, self.cfg.refine)
        t["refine"] = time.perf_counter()
        # 7. merge into the robot's map; the changed cells are the delta
        base = self.map.version
        try:
            self.map = self.map.merge(kf, self.merge_options).map
        except PolyswarmError as e:  # never silently: counted, logged, pose still tracked
            self.rejected_keyframes += 1
            log.warning("keyframe %d not merged: %s", self.keyframes, e)
        t["merge"] = time.perf_counter()
        delta = self.map.delta_since(base) if self.map.version != base else None
        self.pose = np.array([pose[0], pose[1], float(wrap(pose[2]))])
        self._kf_pose, self._kf_odom = self.pose.copy(), odom
        self.selector.mark(odom)
        self._keyframe_requested = False
        self.keyframes += 1
        names = ["points", "icp", "polygon", "refine", "merge"]
        prev, ms = t["start"], {}
        for name in names:
            ms[name] = (t[name] - prev) * 1e3
            prev = t[name]
        ms["total"] = (t["merge"] - t["start"]) * 1e3
        return SlamStep(self.pose.copy(), True, delta, res, how, ms)
