"""The odometry's distance scale, learnt online from the keyframes ICP pinned down.

A wheel whose radius is 1 % off makes every distance the odometry reports 1 % off. ICP
removes that error wherever the scan constrains the pose in every direction, but in a
corridor with no end in sight it keeps the odometry along the corridor (the degeneracy
guard in ``polyswarm.slam.icp``), so the scale error goes straight into the map: on the
thesis's loop world with the TurtleBot3's odometry noise (a distance scale error of 1 %
as one sigma, drawn per robot), 44 % of the keyframes were degenerate and the corridors
came out up to 1 m long or short.

The scale is observable on the other keyframes: between two consecutive keyframes that
ICP pinned down in every direction, the aligned motion is the true one and the odometry's
is that times the scale. ``OdometryScale`` keeps the least-squares estimate over those
pairs, shrunk towards 1 by a prior (a wheel's radius is rarely more than ``PRIOR_SIGMA``
off), with each pair weighed by the odometry's own random error (learnt from the pairs'
residuals): s = (sum(icp . odo) + lam) / (sum(odo . odo) + lam), lam = sigma^2 / prior^2.
Old pairs are forgotten over ``MEMORY_M`` of travel. With ``slam.learn_odometry_scale``
PolySLAM multiplies the odometry's distances by it when predicting a pose. It is off by
default: with the TurtleBot3's 3.5 m lidar the estimate was up to 1.8 % wrong and
3-robot explorations gained nothing measurable; the
``thesis-noisy-odometry`` profile turns it on.

    scale = OdometryScale()
    scale.add(odometry_step, icp_step)   # (x m, y m) motions between two keyframes
    pose = compose(kf_pose, scale.correct(relative(kf_odom, odom)))
"""

from __future__ import annotations

import logging
import math

import numpy as np

log = logging.getLogger(__name__)

# one sigma of a wheel's distance scale before any pair is seen: the TurtleBot3's
# odometry noise has 1 % (polyswarm.profiles), worn or mis-inflated tyres a few percent
PRIOR_SIGMA = 0.02
# the random error of one pair's odometry before residuals are seen (m): thesis-sensor
# runs measured 7 mm with the thesis's odometry noise and 27 mm with the TurtleBot3's
# on 0.4 m steps; the larger is the safer start (more shrinkage)
START_SIGMA_M = 0.03
MIN_SIGMA_M = 0.003  # residuals below this are ICP's own noise: not weighed as less
# old pairs count less, by exp(-travel since / MEMORY_M): a tyre wears, a load changes
MEMORY_M = 500.0
# a pair shorter than this says little about distances (the robot turned on the spot)
MIN_STEP_M = 0.1
# a wheel radius off by more than this is a broken robot, not a calibration: an estimate
# outside is a sign of something else (slipping on a carpet, a kidnapping) and not used
PLAUSIBLE = (0.8, 1.25)
# an estimate is logged when it moved this much since it was last logged
LOG_CHANGE = 0.005


class OdometryScale:
    """Least-squares scale of the odometry's distances against ICP's, with forgetting."""

    def __init__(self) -> None:
        self._num = 0.0  # sum of icp . odo (m^2), decayed
        self._den = 0.0  # sum of odo . odo (m^2), decayed
        self._sq = 0.0  # sum of squared residuals (m^2), decayed
        self._n = 0.0  # pairs, decayed
        self.pairs = 0
        self._logged = 1.0

    def add(self, odometry_step, icp_step) -> None:
        """One pair of consecutive keyframes that ICP pinned down in every direction:
        the odometry's motion and ICP's, (x m, y m) each in its previous keyframe's frame."""
        odo = np.asarray(odometry_step, dtype=float)[:2]
        icp = np.asarray(icp_step, dtype=float)[:2]
        d = float(np.hypot(*odo))
        if d < MIN_STEP_M or not (np.isfinite(odo).all() and np.isfinite(icp).all()):
            return
        along = float(icp @ odo) / d  # ICP's motion along the odometry's, m
        # against the plain least-squares estimate: one shrunk by the prior would count
        # the scale error itself as noise (and shrink the more for it)
        residual = along - (self._num / self._den if self._den > 0 else 1.0) * d
        keep = math.exp(-d / MEMORY_M)
        self._num = keep * self._num + along * d
        self._den = keep * self._den + d * d
        self._sq = keep * self._sq + residual * residual
        self._n = keep * self._n + 1.0
        self.pairs += 1
        s = self.scale
        if abs(s - self._logged) >= LOG_CHANGE:
            log.info("odometry distance scale %.4f (%d keyframe pairs)", s, self.pairs)
            self._logged = s

    def state(self) -> dict:
        """What the estimate is made of (an agent persists it: a restarted agent keeps its
        robot's calibration)."""
        return {
            "num": self._num,
            "den": self._den,
            "sq": self._sq,
            "n": self._n,
            "pairs": self.pairs,
        }

    @classmethod
    def from_state(cls, state: dict) -> OdometryScale:
        """The estimate ``state()`` described; ValueError if it is not one."""
        out = cls()
        try:
            num, den, sq, n = (float(state[k]) for k in ("num", "den", "sq", "n"))
            pairs = int(state["pairs"])
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"bad odometry scale state {state!r}") from e
        if not all(math.isfinite(v) for v in (num, den, sq, n)) or min(den, sq, n, pairs) < 0:
            raise ValueError(f"bad odometry scale state {state!r}")
        out._num, out._den, out._sq, out._n, out.pairs = num, den, sq, n, pairs
        out._logged = out.scale
        return out

    @property
    def sigma_m(self) -> float:
        """The random error of one pair's odometry (m), from the residuals so far."""
        if self._n < 1.0:
            return START_SIGMA_M
        # the first residuals are against a young estimate: start_sigma counts as one pair
        rms = math.sqrt((self._sq + START_SIGMA_M**2) / (self._n + 1.0))
        return max(rms, MIN_SIGMA_M)

    @property
    def raw(self) -> float:
        """The estimate, shrunk towards 1 by the prior (1.0 before any pair)."""
        lam = (self.sigma_m / PRIOR_SIGMA) ** 2
        return (self._num + lam) / (self._den + lam)

    @property
    def scale(self) -> float:
        """The scale in use: ICP's distance over the odometry's; 1.0 when the estimate is
        implausible."""
        s = self.raw
        return s if PLAUSIBLE[0] <= s <= PLAUSIBLE[1] else 1.0

    def correct(self, odometry_step) -> np.ndarray:
        """An odometry motion (x m, y m, theta rad) with its distance scaled."""
        step = np.array(odometry_step, dtype=float)
        step[:2] *= self.scale
        return step
