"""Noisy odometry built from a reference trajectory (for logs with corrected poses).

Per increment between consecutive reference poses (distance d, rotation r): the
travelled distance is scaled by (1 + N(0, scale_sigma)), a sideways slip of
N(0, lateral_sigma_per_m * d) is added, and the heading change gets
N(0, heading_sigma_per_rad * |r| + heading_sigma_per_m * d). Seeded.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from polyswarm.se2 import compose, relative


@dataclass(frozen=True)
class IncrementNoise:
    scale_sigma: float = 0.05
    lateral_sigma_per_m: float = 0.01
    heading_sigma_per_rad: float = 0.05
    heading_sigma_per_m: float = 0.02  # rad per metre travelled

    def describe(self) -> dict:
        return {"model": "per-increment (polyswarm.odometry)", **asdict(self)}


def noisy_odometry(reference: np.ndarray, noise: IncrementNoise, seed: int) -> np.ndarray:
    ref = np.asarray(reference, dtype=float)
    rng = np.random.default_rng(seed)
    out = np.zeros_like(ref)
    out[0] = ref[0]
    for k in range(1, len(ref)):
        dx, dy, dth = relative(ref[k - 1], ref[k])
        d = float(np.hypot(dx, dy))
        e = rng.standard_normal(3)
        scale = 1.0 + noise.scale_sigma * e[0]
        dx, dy = dx * scale, dy * scale
        if d > 0:
            lat = noise.lateral_sigma_per_m * d * e[1]
            dx, dy = dx - lat * dy / d, dy + lat * dx / d
        dth += (noise.heading_sigma_per_rad * abs(dth) + noise.heading_sigma_per_m * d) * e[2]
        out[k] = compose(out[k - 1], (dx, dy, dth))
    return out
