"""The other robots of the swarm as a robot agent sees them: their latest poses (in the
shared frame), and the scan returns that are theirs, kept from SLAM. A mixin of
``RobotAgent`` (it keeps ``peers``, ``pose``, ``stats`` and the mount)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from polyswarm.se2 import transform_points
from polyswarm.slam.scan import LaserScan, beam_angles
from protocols.messages import Pose

PEER_FRESH_S = 2.0
# scan returns this close to another robot's last pose (radius 0.2 m, poses 2 Hz at up to
# 0.5 m/s, and both robots' pose errors) are that robot: dropouts for SLAM. In a corridor
# whose ends are out of range, robots are the only features along it; mapped and
# matched, a robot that had moved dragged its teammates' ICP down the corridor (zigzag,
# first lane: jumps of 2.5 and 4.2 m along it)
PEER_MASK_M = 0.6
BLOB_MARGIN_M = 0.15  # a robot's blob of returns may be this much wider than the robot


class Peers:
    """Other robots' poses and the masking of their returns (see the module)."""

    def on_peer_pose(self, rid: str, stamp_s: float, pose: Pose) -> None:
        if rid == self.id or not self.in_shared_frame:
            return
        if rid in self._own_frames and (pose.frame == 0 or pose.own):
            return  # a robot in a frame of its own (still, or again)
        self.peers[rid] = (stamp_s, np.array([pose.x, pose.y]))
        self.behaviour.on_peer(rid, stamp_s, self.peers[rid][1], pose.blocked_by, self.pose)

    def _without_peers(self, scan: LaserScan, now_s: float) -> LaserScan:
        """The scan with returns from other robots (within ``PEER_MASK_M`` of a fresh
        peer pose) turned into dropouts: neither mapped nor matched by ICP."""
        if not self._fresh_peers(now_s):
            return scan
        r = np.asarray(scan.ranges, dtype=float)
        ok = np.isfinite(r)
        mount = self._mount()
        a = beam_angles(scan, mount)
        rr = np.where(ok, r, 0.0)
        ends = np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1) + mount[:2]
        hit = ok & self._near_peers(transform_points(self.pose, ends), now_s)
        if not hit.any():
            return scan
        self.stats.peer_returns_masked += int(hit.sum())
        return replace(scan, ranges=np.where(hit, np.nan, r))

    def _blobs_m(self, now_s: float) -> float:
        """How wide a blob of returns ICP leaves out (``PolySlam.process``): a robot's
        width and a margin while a robot of the swarm may be near that this one cannot
        place (its frame unknown here, or its poses not fresh); 0 otherwise (its returns
        are masked as a peer's)."""
        placed = {rid for rid, (t, _) in self.peers.items() if now_s - t <= PEER_FRESH_S}
        if not self._own_frames - placed - {self.id}:
            return 0.0
        return 2 * self.cfg.nav.robot_radius_m + BLOB_MARGIN_M

    def _fresh_peers(self, now_s: float) -> list[np.ndarray]:
        return [xy for t, xy in self.peers.values() if now_s - t <= PEER_FRESH_S]

    def _near_peers(self, world: np.ndarray, now_s: float) -> np.ndarray:
        """Which points (world frame) lie within ``PEER_MASK_M`` of a fresh peer pose."""
        near = np.zeros(len(world), dtype=bool)
        for xy in self._fresh_peers(now_s):
            near |= np.hypot(*(world - xy).T) <= PEER_MASK_M
        return near
