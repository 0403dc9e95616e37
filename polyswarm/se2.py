"""SE(2) poses as (x, y, theta) arrays: composition, inverse, relative motion.

compose(a, b)   pose b expressed in a's frame, taken to a's parent frame (a (+) b)
relative(a, b)  the motion from a to b, in a's frame (a^-1 (+) b)
"""

from __future__ import annotations

import math

import numpy as np


def wrap(angle):
    """Angles to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi


def compose(a, b) -> np.ndarray:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array(
        [a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], float(wrap(a[2] + b[2]))]
    )


def inverse(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], float(wrap(-a[2]))])


def relative(a, b) -> np.ndarray:
    return compose(inverse(a), b)


def relative_many(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``relative`` for (n, 3) arrays."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap(b[:, 2] - a[:, 2])], axis=1)


def transform_points(pose, xy: np.ndarray) -> np.ndarray:
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    xy = np.asarray(xy, dtype=float)
    return np.stack([x + c * xy[:, 0] - s * xy[:, 1], y + s * xy[:, 0] + c * xy[:, 1]], axis=1)
