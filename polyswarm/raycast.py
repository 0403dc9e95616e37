"""A pure 2D ray caster against line segments (for tests, benchmarks, log tools, and the
coordinator's estimate of the unexplored area behind a frontier).

Typical use::

    ranges = cast_rays((x, y), angles, starts, ends, max_range=30.0)

Returns the distance along each ray to the first segment it crosses, ``inf`` if none
is within ``max_range``. The simulator uses pybullet; this kernel exists so the core
can be tested on geometry checkable by hand (a square room gives known ranges).
"""

from __future__ import annotations

import numpy as np

CHUNK_RAYS = 256  # rays per vectorised block: bounds memory at rays x segments floats


def cast_rays(
    origin,
    angles: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    max_range: float = np.inf,
) -> np.ndarray:
    o = np.asarray(origin, dtype=float)
    angles = np.asarray(angles, dtype=float)
    s = np.asarray(starts, dtype=float).reshape(-1, 2)
    e = np.asarray(ends, dtype=float).reshape(-1, 2)
    out = np.full(len(angles), np.inf)
    if len(s) == 0 or len(angles) == 0:
        return out
    if np.isfinite(max_range):  # drop segments out of reach
        from polyswarm.polymap import point_segment_distance

        keep = point_segment_distance(o, s, e) <= max_range
        s, e = s[keep], e[keep]
        if len(s) == 0:
            return out
    seg = e - s  # (m, 2)
    rel = s - o  # (m, 2)
    for lo in range(0, len(angles), CHUNK_RAYS):
        a = angles[lo : lo + CHUNK_RAYS]
        d = np.stack([np.cos(a), np.sin(a)], axis=1)  # (k, 2)
        # solve o + t d = s + u seg:
        #   t = cross(rel, seg) / cross(d, seg),  u = cross(rel, d) / cross(d, seg)
        den = d[:, None, 0] * seg[None, :, 1] - d[:, None, 1] * seg[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (rel[None, :, 0] * seg[None, :, 1] - rel[None, :, 1] * seg[None, :, 0]) / den
            u = (rel[None, :, 0] * d[:, None, 1] - rel[None, :, 1] * d[:, None, 0]) / den
        ok = (np.abs(den) > 1e-15) & (t > 1e-12) & (u >= 0.0) & (u <= 1.0)
        t = np.where(ok, t, np.inf)
        out[lo : lo + len(a)] = t.min(axis=1)
    out[out > max_range] = np.inf
    return out
