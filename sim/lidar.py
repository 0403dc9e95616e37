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


@dataclass(frozen=True)
class BeamsSeen:
    """What each beam of a sweep met, by ray casting: the true range (inf: nothing within
    range), the incidence angle at the surface (radians from its normal; nan: none),
    and whether the surface is dark or glass (``sim.shapes.dark_surfaces``)."""

    ranges: np.ndarray
    incidence: np.ndarray
    dark: np.ndarray

    @classmethod
    def plain(cls, ranges: np.ndarray) -> BeamsSeen:
        """Ranges alone: every surface met head-on, none dark."""
        r = np.asarray(ranges, dtype=float)
        return cls(r, np.where(np.isfinite(r), 0.0, np.nan), np.zeros(len(r), dtype=bool))


GRAZING_FROM_RAD = math.radians(45.0)  # incidence below this does not add dropouts
GRAZING_FULL_RAD = math.radians(80.0)  # ... above this adds all of dropout_grazing_prob
FAR_STEP = 0.06  # width (share of range_max) of the rise of dropouts with range
MIXED_JUMP_M = 0.3  # neighbouring surfaces this far apart: an edge a beam may straddle


def dropout_probability(seen: BeamsSeen, cfg: LidarConfig) -> np.ndarray:
    """Each beam's probability of returning nothing (see ``LidarConfig``)."""
    x = np.where(np.isfinite(seen.ranges), seen.ranges / cfg.range_max_m, 1.0)
    rise = 1.0 / (1.0 + np.exp(-(x - cfg.dropout_far_from) / FAR_STEP))
    p_range = cfg.dropout_prob + (cfg.dropout_far_prob - cfg.dropout_prob) * rise
    a = np.nan_to_num(seen.incidence, nan=0.0)
    g = np.clip((a - GRAZING_FROM_RAD) / (GRAZING_FULL_RAD - GRAZING_FROM_RAD), 0.0, 1.0)
    p = 1.0 - (1.0 - p_range) * (1.0 - cfg.dropout_grazing_prob * g**2)
    return np.where(seen.dark, np.maximum(p, cfg.dark_dropout_prob), p)


def _correlated_uniform(n: int, run_beams: float, rng: np.random.Generator) -> np.ndarray:
    """Uniform numbers along a sweep, correlated over about ``run_beams`` beams (an AR(1)
    Gaussian sequence through its CDF): thresholded, they fail in runs."""
    from scipy.signal import lfilter
    from scipy.special import ndtr

    e = rng.standard_normal(n + 1)
    if run_beams <= 1.0:
        return ndtr(e[1:])
    rho = math.exp(-1.0 / run_beams)
    # z[k] = rho z[k-1] + sqrt(1 - rho^2) e[k], started from the stationary N(0, 1)
    return ndtr(lfilter([math.sqrt(1.0 - rho * rho)], [1.0, -rho], e[1:], zi=[rho * e[0]])[0])


def measure(seen, cfg: LidarConfig, rng: np.random.Generator) -> np.ndarray:
    """The ranges a driver publishes for the beams of a sweep (``BeamsSeen``, or true
    ranges alone): mixed pixels at edges, Gaussian noise growing with the range,
    dropouts by range, incidence and surface, in runs; every beam without a valid
    return (nothing in range, closer than range_min, a dropout) reported the driver's way
    (``out_of_range``)."""
    if not isinstance(seen, BeamsSeen):
        seen = BeamsSeen.plain(seen)
    true = seen.ranges
    n = len(true)
    hit = np.isfinite(true)
    r = true.copy()
    if cfg.mixed_pixel_prob > 0 and n > 2:
        full = cfg.fov_rad >= 2 * math.pi - 1e-9
        r = _mixed_pixels(r, hit, cfg.mixed_pixel_prob, rng, full)
    sigma = cfg.noise_sigma_m + cfg.noise_sigma_per_m * np.where(hit, r, 0.0)
    r = np.where(hit, r + sigma * rng.standard_normal(n), np.inf)
    r = np.where(hit, np.maximum(r, 0.0), np.inf)
    invalid = ~hit | (r < cfg.range_min_m) | (r >= cfg.range_max_m)
    p = dropout_probability(seen, cfg)
    if p.any():
        invalid |= hit & (_correlated_uniform(n, cfg.dropout_run_beams, rng) < p)
    return np.where(invalid, NO_RETURN_VALUE[OutOfRange(cfg.out_of_range)], r)


def _mixed_pixels(r: np.ndarray, hit: np.ndarray, prob: float, rng, full: bool) -> np.ndarray:
    """At an edge (a neighbour's surface ``MIXED_JUMP_M`` nearer or farther), a beam's
    return falls uniformly between the two surfaces with probability ``prob``; the first
    and last beams are neighbours on a full circle only."""
    out = r.copy()
    for shift in (1, -1):
        other = np.roll(r, shift)
        if not full:
            other[0 if shift == 1 else -1] = np.inf
        gap = np.abs(np.subtract(other, r, out=np.zeros_like(r), where=np.isfinite(other) & hit))
        edge = gap > MIXED_JUMP_M
        mix = edge & (rng.random(len(r)) < prob)
        lo, hi = np.minimum(r, other), np.maximum(r, other)
        out[mix] = lo[mix] + rng.random(int(mix.sum())) * (hi[mix] - lo[mix])
    return out
