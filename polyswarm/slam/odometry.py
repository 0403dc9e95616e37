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
        return {"model": "per-increment (polyswarm.slam.odometry)", **asdict(self)}


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


class OdometryBuffer:
    """The latest odometry poses with their times, to look up the pose at any moment
    (linear between two readings, heading on the short way round; clamped at the ends).

    A scan is matched with the odometry of its time, and a rolling sweep is de-skewed
    with the poses at each of its beams (``polyswarm.slam.scan.deskew_motion``)."""

    def __init__(self, capacity: int = 200) -> None:
        self.capacity = capacity
        self.times: list[float] = []
        self.poses: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.times)

    @property
    def latest_s(self) -> float:
        return self.times[-1] if self.times else -np.inf

    def add(self, t: float, pose) -> bool:
        """Append a reading; a reading older than the last one clears the buffer (the
        source restarted) and returns False."""
        ok = not self.times or t >= self.times[-1]
        if not ok:
            self.times.clear()
            self.poses.clear()
        self.times.append(float(t))
        self.poses.append(np.asarray(pose, dtype=float))
        if len(self.times) > self.capacity:
            del self.times[: -self.capacity // 2]
            del self.poses[: -self.capacity // 2]
        return ok

    def at(self, t: float) -> np.ndarray | None:
        return None if not self.times else self.at_many(np.array([t]))[0]

    def at_many(self, times) -> np.ndarray:
        """(k, 3) poses at ``times`` (seconds)."""
        t = np.asarray(times, dtype=float)
        ts = np.asarray(self.times)
        p = np.asarray(self.poses)
        th = np.unwrap(p[:, 2])
        out = np.stack([np.interp(t, ts, p[:, 0]), np.interp(t, ts, p[:, 1]), np.interp(t, ts, th)])
        out = out.T
        wrapped = (out[:, 2] + np.pi) % (2 * np.pi) - np.pi
        out[:, 2] = np.where(np.abs(out[:, 2]) > np.pi, wrapped, out[:, 2])
        return out
