"""Stage 4's reference: the obstacle vectors of the keyframes near the robot.

ICP does not match against the merged PolyMap: the map is the union of every
keyframe's explored space, so each wall sits on the outer envelope of all the noisy
views of it. On the aces log, ICP started from the reference poses against a map built
at those poses moved the robot 2.8 cm forward on average (heading error std 0.82 deg),
while against the refined polygons of the previous keyframes the bias was 0.0 cm
(std 0.33 deg), and the bias added up to metres of drift. So each keyframe's refined
obstacle vectors are kept in the keyframe's own frame, and a scan is matched against
the keyframes nearest to its predicted pose plus the latest few. Keeping them in the
keyframe's frame lets a pose-graph correction (``polyswarm.slam.posegraph``) move them with
their keyframe.

    store = KeyframeStore(max_keyframes=20, radius_m=10.0, recent=5)
    store.add(pose, polygon)                   # a refined keyframe polygon, world frame
    starts, ends = store.reference(pred_pose)  # obstacle vectors to match against
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyswarm.polymap import Ring, TypedPolygon, VectorType
from polyswarm.se2 import inverse, transform_points


def move_polygon(polygon: TypedPolygon, pose) -> TypedPolygon:
    """The polygon moved rigidly by ``pose`` (its vector types unchanged)."""
    return TypedPolygon(
        Ring(transform_points(pose, polygon.shell.xy), polygon.shell.types),
        tuple(Ring(transform_points(pose, h.xy), h.types) for h in polygon.holes),
    )


@dataclass
class StoredKeyframe:
    pose: np.ndarray  # (x, y, theta) in the map frame; moved by pose-graph corrections
    starts: np.ndarray  # obstacle vectors in the keyframe's own frame
    ends: np.ndarray
    polygon: TypedPolygon  # the refined keyframe polygon in its own frame

    def polygon_in_map(self) -> TypedPolygon:
        return move_polygon(self.polygon, self.pose)


class KeyframeStore:
    """Obstacle vectors of every keyframe, in the keyframe's frame (owned by one SLAM)."""

    def __init__(self, max_keyframes: int, radius_m: float, recent: int) -> None:
        self.max_keyframes, self.radius_m, self.recent = max_keyframes, radius_m, recent
        self.keyframes: list[StoredKeyframe] = []
        self._xy = np.zeros((0, 2))  # keyframe positions, for the spatial look-up

    def __len__(self) -> int:
        return len(self.keyframes)

    def add(self, pose, polygon: TypedPolygon) -> None:
        starts, ends, types = polygon.segments()
        ob = types == VectorType.OBSTACLE
        pose = np.array(pose, dtype=float)
        to_local = inverse(pose)
        self.keyframes.append(
            StoredKeyframe(
                pose,
                transform_points(to_local, starts[ob]),
                transform_points(to_local, ends[ob]),
                move_polygon(polygon, to_local),
            )
        )
        self._xy = np.vstack([self._xy, pose[None, :2]])

    def set_poses(self, poses: np.ndarray) -> None:
        """New poses for all keyframes (after a pose-graph optimisation)."""
        poses = np.asarray(poses, dtype=float)
        for kf, p in zip(self.keyframes, poses, strict=True):
            kf.pose = p.copy()
        self._xy = poses[:, :2].copy()

    def nearest(
        self,
        pose,
        exclude_after: int | None = None,
        radius_m: float | None = None,
        limit: int | None = None,
    ) -> np.ndarray:
        """Indices of the keyframes within ``radius_m`` (default: the store's) of ``pose``,
        nearest first, at most ``limit`` (default ``max_keyframes``); ``exclude_after``
        keeps only keyframes older than that index."""
        n = len(self.keyframes) if exclude_after is None else max(0, exclude_after)
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        radius_m = self.radius_m if radius_m is None else radius_m
        limit = self.max_keyframes if limit is None else limit
        d = np.hypot(self._xy[:n, 0] - pose[0], self._xy[:n, 1] - pose[1])
        near = np.flatnonzero(d < radius_m)
        return near[np.argsort(d[near], kind="stable")][:limit]

    def vectors(self, which) -> tuple[np.ndarray, np.ndarray]:
        """World-frame obstacle vectors of the keyframes ``which``."""
        starts, ends = [np.zeros((0, 2))], [np.zeros((0, 2))]
        for i in which:
            kf = self.keyframes[int(i)]
            starts.append(transform_points(kf.pose, kf.starts))
            ends.append(transform_points(kf.pose, kf.ends))
        return np.vstack(starts), np.vstack(ends)

    def reference(self, pose) -> tuple[np.ndarray, np.ndarray]:
        """The vectors a scan taken near ``pose`` is matched against."""
        n = len(self.keyframes)
        which = set(self.nearest(pose).tolist()) | set(range(max(0, n - self.recent), n))
        return self.vectors(sorted(which))
