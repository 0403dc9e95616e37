"""The simulated lidar's model, apart from ray casting: beam layout and timing, range
noise, dropouts and how a driver reports a beam that saw nothing.

Typical use (``sim.simulation`` does this)::

    angles = beam_angles(cfg)                       # radians, sensor frame
    sched = BeamSchedule.make(cfg, angles, steps_per_scan=10, dt=0.02)
    ranges = measure(true_ranges, cfg, rng)         # what the driver publishes

A spinning lidar (``rolling``) takes its beams one after the other over the sweep
(1 / rate_hz): beam ``j`` at ``j * time_increment`` after the first, with
``time_increment = sweep * |angle increment| / 2 pi`` (the mirror turns a full circle
per sweep, also for a lidar that only reports 270 degrees of it). The scan is published
when the sweep ends, stamped with its first beam's time, as ROS drivers do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyswarm.config import LidarConfig, OutOfRange

# what each driver convention publishes for a beam with no valid return
NO_RETURN_VALUE = {OutOfRange.INF: math.inf, OutOfRange.NAN: math.nan, OutOfRange.ZERO: 0.0}


def beam_angles(cfg: LidarConfig) -> np.ndarray:
    """Beam directions (radians, counter-clockwise, 0 straight ahead): a full circle
    starts behind the robot; a partial field of view is centred ahead."""
    if cfg.fov_rad >= 2 * math.pi - 1e-9:
        return -math.pi + np.arange(cfg.beams) * (2 * math.pi / cfg.beams)
    return np.linspace(-cfg.fov_rad / 2, cfg.fov_rad / 2, cfg.beams)


@dataclass(frozen=True)
class BeamSchedule:
    """When, within a sweep of ``steps`` physics steps of ``dt`` seconds, each beam is
    taken: during step ``step[j]`` (0 = the sweep's first), at fraction ``frac[j]`` of it."""

    step: np.ndarray  # (beams,) int
    frac: np.ndarray  # (beams,) in [0, 1)
    time_increment_s: float  # between consecutive beams (0: all at once)
    scan_time_s: float  # the sweep

    @classmethod
    def make(cls, cfg: LidarConfig, angles: np.ndarray, steps: int, dt: float) -> BeamSchedule:
        sweep = steps * dt
        n = len(angles)
        if not cfg.rolling or n < 2:  # every beam at the end of the sweep
            return cls(np.full(n, steps - 1), np.ones(n) - 1e-12, 0.0, sweep)
        inc = abs(float(angles[1] - angles[0]))
        dt_beam = sweep * inc / (2 * math.pi)
        t = np.arange(n) * dt_beam
        step = np.minimum((t / dt).astype(int), steps - 1)
        return cls(step, t / dt - step, dt_beam, sweep)


def measure(true_ranges: np.ndarray, cfg: LidarConfig, rng: np.random.Generator) -> np.ndarray:
    """The ranges a driver publishes for beams whose true ranges (inf: nothing within
    range) are given: Gaussian noise growing with the range, dropouts, and every beam
    without a valid return (nothing in range, closer than range_min, a dropout) reported
    the driver's way (``out_of_range``)."""
    n = len(true_ranges)
    hit = np.isfinite(true_ranges)
    sigma = cfg.noise_sigma_m + cfg.noise_sigma_per_m * np.where(hit, true_ranges, 0.0)
    r = np.where(hit, true_ranges + sigma * rng.standard_normal(n), np.inf)
    r = np.where(hit, np.maximum(r, 0.0), np.inf)
    invalid = ~hit | (r < cfg.range_min_m) | (r >= cfg.range_max_m)
    if cfg.dropout_prob > 0:
        invalid |= rng.random(n) < cfg.dropout_prob
    return np.where(invalid, NO_RETURN_VALUE[OutOfRange(cfg.out_of_range)], r)
