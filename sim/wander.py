"""A reactive wander controller for looking at the simulator (not for exploration).

Drive forward while the sector ahead is clear, otherwise turn towards the side with
more room; a little seeded randomness keeps robots from repeating loops.
"""

from __future__ import annotations

import numpy as np

from polyswarm.slam.scan import LaserScan

CLEAR_M = 0.9  # turn away when anything is closer than this ahead
AHEAD_RAD = 0.5  # half-width of the sector that must be clear


class Wander:
    def __init__(self, seed: int = 0, speed: float = 0.4, turn: float = 1.0) -> None:
        self.rng = np.random.default_rng(seed)
        self.speed, self.turn = speed, turn
        self.bias = 0.0

    def command(self, scan: LaserScan) -> tuple[float, float]:
        r = np.nan_to_num(np.asarray(scan.ranges, dtype=float), nan=0.0, posinf=scan.range_max)
        a = scan.angles
        ahead = np.abs(a) < AHEAD_RAD
        if ahead.any() and r[ahead].min() < CLEAR_M:
            left = r[(a > 0) & (a < 1.6)].mean() if ((a > 0) & (a < 1.6)).any() else 0.0
            right = r[(a < 0) & (a > -1.6)].mean() if ((a < 0) & (a > -1.6)).any() else 0.0
            return 0.0, self.turn if left >= right else -self.turn
        self.bias = 0.9 * self.bias + 0.1 * self.rng.normal(0.0, 0.6)
        return self.speed, self.bias
