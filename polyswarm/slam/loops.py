"""Stage 4 of PolySLAM: loop closure. A keyframe is matched with the old keyframes near
it (ICP, after a correlative search where tracking may have drifted beyond ICP's reach);
an accepted loop becomes a pose-graph edge, and a loop that disagrees with tracking
optimises the graph and moves the keyframes, the evidence and the map with it
(``polyswarm.slam.follow``); ``rebuild_map`` merges every keyframe again at its
optimised pose. A mixin of ``PolySlam``: it uses the SLAM's graph, store,
ICP and map."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import GridPolyMap
from polyswarm.se2 import compose, relative, wrap
from polyswarm.slam.follow import correct
from polyswarm.slam.icp import IcpResult
from polyswarm.slam.loopsearch import correlative_search

log = logging.getLogger(__name__)

# a heading change of 1 rad moves the scan points 2 m away (typical indoor ranges) by
# about 2 m: how loop corrections of heading and position are weighed against each other
METRES_PER_RADIAN = 2.0
WEAK_SIGMA_M = 100.0  # std of a loop edge along a corridor: no information there


def rotate(v, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


class LoopClosing:
    """Loop search, graph optimisation and the map following it (see the module)."""

    def _close_loop(self, node: int, pose, valid, origin) -> np.ndarray:
        """Look for a loop from keyframe ``node`` at ``pose``; its pose after any
        correction."""
        lc = self.cfg.loop_closure
        # how far tracking may have drifted since the last loop: the wide search's window
        window = lc.search_window(self._travel_since_loop_m)
        # the old submap: keyframes near the pose, all older than min_age_keyframes
        old = self.store.nearest(
            pose,
            node - lc.min_age_keyframes,
            radius_m=lc.radius_m + window - lc.search_window_m,
            limit=lc.keyframes,
        )
        if len(old) == 0:
            return pose
        s, e = self.store.vectors(old)
        m = self.icp.align(valid, pose, s, e, origin)
        ok = self._loop_accepted(m, pose, len(valid), window)
        waited = min(node - self._last_loop, node - self._last_search)
        if not ok and lc.search_window_m > 0 and waited >= lc.search_every_keyframes:
            # tracking may have drifted beyond ICP's reach: search a wide window first
            self._last_search = node
            start, _, ambiguous = correlative_search(valid, pose, s, e, window)
            if not ambiguous:
                m = self.icp.align(valid, start, s, e, origin)
                ok = self._loop_accepted(m, pose, len(valid), window)
        if not ok:
            return pose
        self._last_loop = node
        self._travel_since_loop_m = 0.0
        shift = float(np.hypot(*(m.pose[:2] - pose[:2])))
        anchor = int(old[0])
        anchor_pose = self.store.keyframes[anchor].pose
        self.graph.add_edge(
            anchor,
            node,
            relative(anchor_pose, m.pose),
            lc.loop_sigma_m,
            lc.loop_sigma_rad,
            loop=True,
            # in a corridor the loop says nothing along it
            weak_axis=None
            if m.degenerate_axis is None
            else rotate(m.degenerate_axis, -anchor_pose[2]),
            weak_sigma_m=WEAK_SIGMA_M,
        )
        if m.degenerate_axis is not None:  # keep the tracked position along the corridor
            along = m.degenerate_axis @ (m.pose[:2] - pose[:2])
            m = replace(m, pose=np.r_[m.pose[:2] - along * m.degenerate_axis, m.pose[2]])
            shift = float(np.hypot(*(m.pose[:2] - pose[:2])))
        turn = abs(float(wrap(m.pose[2] - pose[2])))
        if shift + turn * METRES_PER_RADIAN < lc.optimise_above_m:
            return pose  # the loop agrees with tracking: nothing to correct yet
        log.debug("loop %d -> %d closed: moved %.3f m, %.2f deg", anchor, node, shift, turn)
        return self._optimise_graph()

    def _optimise_graph(self) -> np.ndarray:
        """Optimise the pose graph, move the keyframes and the map with it (once per
        keyframe step); the new keyframe's pose."""
        self._optimise = False
        poses = self.graph.optimise()
        self.store.set_poses(poses[:-1])
        if self.evidence is not None:
            self.evidence.move_to(poses)
        if self._follows:
            self._follow()
        return poses[-1]

    def _follow(self) -> None:
        """Merge again the cells of keyframes the optimisation moved (polyswarm.slam.follow)."""
        kfs = self.store.keyframes
        poses = {k: compose(kfs[k].pose, f) for k, f in self._frames.items()}
        self.map, op, info = correct(self.map, self.atlas, poses)
        if op is not None:
            if self._correction is not None:  # one optimisation per keyframe: never here
                raise PolyswarmError("two corrections in one keyframe step")
            self._correction = op
            self.corrections.append(info)

    def _loop_accepted(self, m: IcpResult, pose, n_points: int, window_m: float) -> bool:
        lc = self.cfg.loop_closure
        return bool(
            m.converged
            and m.inliers >= lc.min_inlier_fraction * n_points
            and m.rmse_m <= lc.max_rmse_m
            and np.hypot(*(m.pose[:2] - pose[:2]))
            <= lc.max_correction_m + window_m - lc.search_window_m
        )

    @property
    def loops_closed(self) -> int:
        return self.graph.loop_edges

    def rebuild_map(self) -> GridPolyMap:
        """A new map of every keyframe merged at its optimised pose, ``rebuild_batch``
        consecutive keyframes a pass (a batch that fails is merged one by one)."""
        pmap = GridPolyMap(self.map.cell_size)
        kfs = self.store.keyframes
        step = self.cfg.rebuild_batch
        for k0 in range(0, len(kfs), step):
            polys = [kf.polygon_in_map() for kf in kfs[k0 : k0 + step]]
            try:
                pmap = pmap.merge_many(polys, self.merge_options).map
                continue
            except PolyswarmError as e:
                log.info("keyframes %d-%d merged one by one: %s", k0, k0 + len(polys) - 1, e)
            for k, poly in enumerate(polys, start=k0):
                try:
                    pmap = pmap.merge(poly, self.merge_options).map
                except PolyswarmError as e:
                    self.rejected_keyframes += 1
                    log.warning("keyframe %d not merged into the rebuilt map: %s", k, e)
        return pmap
