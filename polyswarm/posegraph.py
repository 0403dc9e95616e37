"""Global optimisation of keyframe poses (the thesis' future work, section 6.2).

Nodes are keyframe poses; an edge says "keyframe j seen from keyframe i lies at z"
(an SE(2) motion in i's frame) with a standard deviation in metres and radians.
Sequential edges come from tracking (each keyframe against the one before), loop
edges from matching a scan against an old part of the map. ``optimise`` minimises
the weighted edge errors with a robust (Huber) loss, so a wrong loop edge is
down-weighted rather than bending the whole trajectory; node 0 stays fixed (it
anchors the map frame).

    g = PoseGraph()
    a = g.add_node((0, 0, 0)); b = g.add_node((1, 0, 0))
    g.add_edge(a, b, (1.0, 0.0, 0.0), sigma_m=0.05, sigma_rad=0.01)
    poses = g.optimise()
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from scipy.optimize import least_squares

from polyswarm.errors import PolyswarmError
from polyswarm.se2 import relative_many, wrap

log = logging.getLogger(__name__)

HUBER_SCALE = 3.0  # edge errors beyond 3 standard deviations count linearly, not squared


@dataclass(frozen=True)
class Edge:
    i: int
    j: int
    z: np.ndarray  # measured pose of j in i's frame
    sqrt_info: np.ndarray  # 3x3: weighted error = sqrt_info @ (x, y, theta) error
    loop: bool


def sqrt_information(sigma_m: float, sigma_rad: float, weak_axis=None, weak_sigma_m=None):
    """Weights of an edge error: ``sigma_m`` in both directions, or ``weak_sigma_m`` along
    ``weak_axis`` (a unit vector in the edge's frame; a corridor's direction, where ICP
    kept the odometry) and ``sigma_m`` across it."""
    w = np.diag([1 / sigma_m, 1 / sigma_m, 1 / sigma_rad])
    if weak_axis is not None:
        a = np.asarray(weak_axis, dtype=float) / np.hypot(*weak_axis)
        R = np.array([[a[0], a[1]], [-a[1], a[0]]])  # rows: along, across the weak axis
        w[:2, :2] = np.diag([1 / weak_sigma_m, 1 / sigma_m]) @ R
    return w


class PoseGraph:
    def __init__(self) -> None:
        self._poses: list[np.ndarray] = []
        self.edges: list[Edge] = []

    def __len__(self) -> int:
        return len(self._poses)

    @property
    def poses(self) -> np.ndarray:
        return np.array(self._poses).reshape(-1, 3)

    def add_node(self, pose) -> int:
        self._poses.append(np.array(pose, dtype=float))
        return len(self._poses) - 1

    def add_edge(
        self,
        i: int,
        j: int,
        z,
        sigma_m: float,
        sigma_rad: float,
        loop=False,
        weak_axis=None,
        weak_sigma_m: float | None = None,
    ) -> None:
        """An edge i -> j measuring ``z``; see ``sqrt_information`` for the weights."""
        n = len(self._poses)
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise PolyswarmError(f"pose graph edge {i}->{j} does not join two of {n} nodes")
        if sigma_m <= 0 or sigma_rad <= 0 or (weak_axis is not None and not weak_sigma_m):
            raise PolyswarmError("pose graph edge needs positive standard deviations")
        w = sqrt_information(sigma_m, sigma_rad, weak_axis, weak_sigma_m)
        self.edges.append(Edge(i, j, np.array(z, dtype=float), w, loop))

    @property
    def loop_edges(self) -> int:
        return sum(e.loop for e in self.edges)

    def residuals(self, poses: np.ndarray) -> np.ndarray:
        """Weighted errors of all edges, 3 per edge (x, y, theta)."""
        i = np.array([e.i for e in self.edges])
        j = np.array([e.j for e in self.edges])
        z = np.array([e.z for e in self.edges])
        w = np.array([e.sqrt_info for e in self.edges])
        err = relative_many(poses[i], poses[j]) - z
        err[:, 2] = wrap(err[:, 2])
        return np.einsum("kab,kb->ka", w, err).ravel()

    def optimise(self, max_evaluations: int = 50) -> np.ndarray:
        """Optimised poses (node 0 fixed); the graph keeps them as its new estimate."""
        poses0 = self.poses
        n = len(poses0)
        if n < 2 or not self.edges:
            return poses0
        free = poses0[1:].ravel()

        def fun(x: np.ndarray) -> np.ndarray:
            return self.residuals(np.vstack([poses0[:1], x.reshape(-1, 3)]))

        # each edge's 3 residuals depend on the 3 coordinates of its two nodes
        rows, cols = [], []
        for k, e in enumerate(self.edges):
            for node in (e.i, e.j):
                if node == 0:
                    continue
                for r in range(3):
                    rows += [3 * k + r] * 3
                    cols += [3 * (node - 1) + c for c in range(3)]
        sparsity = scipy.sparse.coo_matrix(
            (np.ones(len(rows)), (rows, cols)), shape=(3 * len(self.edges), 3 * (n - 1))
        )
        res = least_squares(
            fun,
            free,
            jac_sparsity=sparsity,
            loss="huber",
            f_scale=HUBER_SCALE,
            max_nfev=max_evaluations,
            method="trf",
        )
        out = np.vstack([poses0[:1], res.x.reshape(-1, 3)])
        out[:, 2] = wrap(out[:, 2])
        log.debug(
            "pose graph: %d nodes, %d edges (%d loops), cost %.3g -> %.3g",
            n,
            len(self.edges),
            self.loop_edges,
            0.5 * np.sum(fun(free) ** 2),
            res.cost,
        )
        self._poses = [p for p in out]
        return out
