"""Global optimisation of keyframe poses (the thesis' future work, section 6.2).

Nodes are keyframe poses; an edge says "keyframe j seen from keyframe i lies at z"
(an SE(2) motion in i's frame) with a standard deviation in metres and radians.
Sequential edges come from tracking (each keyframe against the one before), loop
edges from matching a scan against an old part of the map. ``optimise`` minimises
the weighted edge errors with a robust (Huber) loss, so a wrong loop edge is
down-weighted rather than bending the whole trajectory; node 0 stays fixed (it
anchors the map frame), unless the graph holds *priors*: poses of nodes in the map
frame that others measured (``set_priors``: the swarm's joint pose graph,
``polyswarm.frames.jointgraph``); then the priors hold the frame and node 0 moves too.

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
import scipy.sparse.linalg

from polyswarm.errors import PolyswarmError
from polyswarm.se2 import compose, relative_many, wrap

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
        self.priors: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # node -> (pose, sqrt_info)

    def __len__(self) -> int:
        return len(self._poses)

    @property
    def poses(self) -> np.ndarray:
        return np.array(self._poses).reshape(-1, 3)

    def move_all(self, frame) -> None:
        """Every node moved by ``frame`` (x m, y m, theta rad): the graph now lives in the
        frame in which its old frame lies at ``frame``. Edges are relative: unchanged;
        priors move with the nodes."""
        self._poses = [compose(frame, p) for p in self._poses]
        self.priors = {k: (compose(frame, p), w) for k, (p, w) in self.priors.items()}

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

    def set_priors(self, poses: dict[int, np.ndarray], sigma_m: float, sigma_rad: float) -> None:
        """Replace the priors: node -> its pose in the map frame (x m, y m, theta rad),
        each with standard deviations ``sigma_m`` and ``sigma_rad``."""
        n = len(self._poses)
        if any(not 0 <= k < n for k in poses) or sigma_m <= 0 or sigma_rad <= 0:
            raise PolyswarmError(f"priors on nodes {sorted(poses)[:5]}... of a graph of {n}")
        w = sqrt_information(sigma_m, sigma_rad)
        self.priors = {int(k): (np.array(p, dtype=float), w) for k, p in poses.items()}

    @property
    def loop_edges(self) -> int:
        return sum(e.loop for e in self.edges)

    def _arrays(self) -> tuple[np.ndarray, ...]:
        i = np.array([e.i for e in self.edges])
        j = np.array([e.j for e in self.edges])
        return (
            i,
            j,
            np.array([e.z for e in self.edges]),
            np.array([e.sqrt_info for e in self.edges]),
        )

    def residuals(self, poses: np.ndarray, arrays=None) -> np.ndarray:
        """Weighted errors of all edges, 3 per edge (x, y, theta)."""
        i, j, z, w = self._arrays() if arrays is None else arrays
        err = relative_many(poses[i], poses[j]) - z
        err[:, 2] = wrap(err[:, 2])
        out = np.einsum("kab,kb->ka", w, err).ravel()
        if not self.priors:
            return out
        k, zp, wp = self._prior_arrays()
        perr = poses[k] - zp
        perr[:, 2] = wrap(perr[:, 2])
        return np.concatenate([out, np.einsum("kab,kb->ka", wp, perr).ravel()])

    def _prior_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = np.array(sorted(self.priors), dtype=int)
        return (
            k,
            np.array([self.priors[n][0] for n in k]).reshape(-1, 3),
            np.array([self.priors[n][1] for n in k]).reshape(-1, 3, 3),
        )

    def optimise(self, max_iterations: int = 30) -> np.ndarray:
        """Optimised poses (node 0 fixed, unless priors hold the frame); the graph keeps
        them as its new estimate.

        Sparse Gauss-Newton with the edges' analytic Jacobians: plain least squares
        first (a true loop edge with a large error must pull), then iteratively
        reweighted with the Huber loss (edges and priors beyond ``HUBER_SCALE`` sigmas
        count linearly, so one wrong loop edge does not bend the trajectory)."""
        poses = self.poses
        n = len(poses)
        if (n < 2 or not self.edges) and not self.priors:
            return poses
        arrays = self._arrays() if self.edges else None
        free = 0 if self.priors else 1  # the first free node
        cost0 = 0.5 * float(np.sum(self.residuals(poses, arrays) ** 2))
        for it in range(max_iterations):
            robust = it >= max_iterations // 3
            err, J = self._system(poses, arrays, robust)
            J = J.tocsc()[:, 3 * free :]
            H = (J.T @ J).tocsc() + scipy.sparse.identity(3 * (n - free)) * 1e-9
            step = scipy.sparse.linalg.spsolve(H, -(J.T @ err))
            poses[free:] += step.reshape(-1, 3)
            poses[:, 2] = wrap(poses[:, 2])
            if np.abs(step).max() < 1e-6 and robust:
                break
        log.debug(
            "pose graph: %d nodes, %d edges (%d loops), %d priors, cost %.3g -> %.3g",
            n,
            len(self.edges),
            self.loop_edges,
            len(self.priors),
            cost0,
            0.5 * float(np.sum(self.residuals(poses, arrays) ** 2)),
        )
        self._poses = [p for p in poses]
        return poses

    def _system(self, poses: np.ndarray, arrays, robust: bool):
        """The weighted errors (edges, then priors) and their sparse Jacobian, Huber
        weighted when ``robust``."""
        n = len(poses)
        blocks, cols, errs = [], [], []
        if arrays is not None:
            i, j, z, w = arrays
            r, Ji, Jj = _linearise(poses, i, j, z)
            wr = np.einsum("kab,kb->ka", w, r)
            Wi, Wj = np.einsum("kab,kbc->kac", w, Ji), np.einsum("kab,kbc->kac", w, Jj)
            if robust:
                h = _huber(wr)
                wr, Wi, Wj = wr * h[:, None], Wi * h[:, None, None], Wj * h[:, None, None]
            blocks += [Wi, Wj]
            cols += [_cols(i), _cols(j)]
            errs.append(wr)
        if self.priors:
            k, zp, wp = self._prior_arrays()
            r = poses[k] - zp
            r[:, 2] = wrap(r[:, 2])
            wr, Wk = np.einsum("kab,kb->ka", wp, r), wp.copy()  # d(error)/d(pose) = I
            if robust:
                h = _huber(wr)
                wr, Wk = wr * h[:, None], Wk * h[:, None, None]
            blocks.append(Wk)
            cols.append(_cols(k))
            errs.append(wr)
        e = np.concatenate(errs)
        m = len(e)
        rows = np.repeat(np.arange(3 * m).reshape(m, 3, 1), 3, axis=2).ravel()
        m_edges = len(self.edges) if arrays is not None else 0
        edge_rows = rows[: 9 * m_edges]
        row_idx = [edge_rows, edge_rows] if arrays is not None else []
        if self.priors:
            row_idx.append(rows[9 * m_edges :])
        J = scipy.sparse.csr_matrix(
            (
                np.concatenate([b.ravel() for b in blocks]),
                (np.concatenate(row_idx), np.concatenate(cols)),
            ),
            shape=(3 * m, 3 * n),
        )
        return e.ravel(), J


def _huber(wr: np.ndarray) -> np.ndarray:
    """Square roots of the Huber weights, per edge, from its weighted error's norm."""
    norm = np.linalg.norm(wr, axis=1)
    return np.sqrt(np.minimum(1.0, HUBER_SCALE / np.maximum(norm, 1e-12)))


def _cols(nodes: np.ndarray) -> np.ndarray:
    """Column indices of a (3 x 3) block per edge for the given nodes."""
    return np.broadcast_to((3 * nodes)[:, None, None] + np.arange(3), (len(nodes), 3, 3)).ravel()


def _linearise(poses, i, j, z):
    """Edge errors and their Jacobians with respect to the poses of i and j."""
    a, b = poses[i], poses[j]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    r = relative_many(a, b) - z
    r[:, 2] = wrap(r[:, 2])
    m = len(i)
    Ji, Jj = np.zeros((m, 3, 3)), np.zeros((m, 3, 3))
    Jj[:, 0, 0], Jj[:, 0, 1], Jj[:, 1, 0], Jj[:, 1, 1], Jj[:, 2, 2] = c, s, -s, c, 1.0
    Ji[:, :2, :2] = -Jj[:, :2, :2]
    Ji[:, 0, 2] = -s * dx + c * dy
    Ji[:, 1, 2] = -c * dx - s * dy
    Ji[:, 2, 2] = -1.0
    return r, Ji, Jj
