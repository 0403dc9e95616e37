"""Named robot profiles: a lidar, a base and its odometry noise, each figure sourced.

A profile fills ``sim.lidar``, ``sim.robot``, ``sim.odometry_noise`` and
``nav.robot_radius_m`` of the configuration; anything a TOML file or a command-line
option sets explicitly wins over it. Select one with ``profile = "turtlebot3"`` in TOML
or ``--profile turtlebot3`` on the command line.

    overrides = PROFILES["turtlebot4"].overrides()   # nested dict of config values
    profile_names()                                  # ("thesis", "turtlebot3", ...)

Profiles are plain data (validated when applied, like any TOML), so this module
imports nothing of the configuration.

Odometry noise: the simulator's odometry error is a random walk per metre and per
radian plus a systematic part drawn once per robot (a wheel-radius error scales every
distance, a wheel-base error every turn: Borenstein's E_d and E_b). Anchor: the real
wheel odometry in the Radish logs (``../shared/data/README.md``) drifts about 0.02-0.09 m
and 0.1-4 degrees per metre driven against the corrected poses; the real profiles sit
inside that band, the thesis profile at its gentle end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# the slam values a profile may set for its lidar's noise, as the thesis's sensor has them
# (a profile that does not set one gets this value, so that switching profiles resets it)
NOISE_DEPENDENT_SLAM = {"refine": {"inlier_threshold_m": 0.03}}


@dataclass(frozen=True)
class Profile:
    name: str
    summary: str
    lidar: dict = field(default_factory=dict)  # sim.lidar values
    base: dict = field(default_factory=dict)  # sim.robot values
    odometry_noise: dict = field(default_factory=dict)  # sim.odometry_noise values
    slam: dict = field(default_factory=dict)  # slam values that depend on the lidar

    def overrides(self) -> dict:
        """The configuration values this profile sets (nested like the TOML file)."""
        out: dict = {
            "sim": {
                "lidar": dict(self.lidar),
                "robot": dict(self.base),
                "odometry_noise": dict(self.odometry_noise),
            },
            "slam": NOISE_DEPENDENT_SLAM | self.slam,
        }
        if "radius_m" in self.base:  # the planner's disc is the base's footprint
            out["nav"] = {"robot_radius_m": self.base["radius_m"]}
        return out


THESIS = Profile(
    "thesis",
    "the thesis's simulated sensor (Dichtl 2019, chapter 5.3) on a 0.5 m/s base",
    lidar={
        "fov_rad": math.radians(270.0),
        "beams": 720,
        "range_min_m": 0.05,
        "range_max_m": 30.0,
        "rate_hz": 10.0,
        "noise_sigma_m": 0.01,
        "noise_sigma_per_m": 0.0,
        "dropout_prob": 0.0,
        "out_of_range": "inf",
        "rolling": False,  # the thesis's simulator took each scan at one instant
    },
    base={
        "radius_m": 0.2,
        "max_linear_mps": 0.5,
        "max_angular_radps": 1.5,
        "max_linear_accel_mps2": 1.0,
        "max_angular_accel_radps2": 3.0,
    },
    odometry_noise={
        "trans_sigma_per_sqrt_m": 0.01,
        "lateral_sigma_per_sqrt_m": 0.005,
        "rot_sigma_per_sqrt_rad": 0.01,
        "rot_sigma_per_sqrt_m": 0.005,
        "scale_sigma": 0.0,
        "turn_scale_sigma": 0.0,
    },
)

TURTLEBOT3 = Profile(
    "turtlebot3",
    "TurtleBot3 Burger with its LDS-01 lidar",
    # ROBOTIS e-Manual, LDS-01 appendix: 360 degrees at 1 degree, 120-3,500 mm, 300 rpm
    # (5 Hz), precision +-10 mm below 0.5 m and +-3.5 % beyond (taken as two sigma:
    # 1.75 % of the range). The ROS driver (hls_lfcd_lds_driver) publishes a beam with
    # no return as 0.0. Dropouts on dark and shiny surfaces: 2 %, as seen by users.
    lidar={
        "fov_rad": 2 * math.pi,
        "beams": 360,
        "range_min_m": 0.12,
        "range_max_m": 3.5,
        "rate_hz": 5.0,
        "noise_sigma_m": 0.01,
        "noise_sigma_per_m": 0.0175,
        "dropout_prob": 0.02,
        "out_of_range": "zero",
        "rolling": True,
    },
    # e-Manual, TurtleBot3 specifications (Burger): 0.22 m/s, 2.84 rad/s, 138 x 178 mm;
    # radius 0.105 m and accelerations 2.5 m/s2, 3.2 rad/s2 as turtlebot3_navigation2's
    # burger.yaml gives them
    base={
        "radius_m": 0.105,
        "max_linear_mps": 0.22,
        "max_angular_radps": 2.84,
        "max_linear_accel_mps2": 2.5,
        "max_angular_accel_radps2": 3.2,
    },
    # small wheels on a light body: the noisy end of the logs' band (4 cm and 1.7 degrees
    # per metre as one sigma, plus 1 % distance and 2 % turn scale errors per robot)
    # line fitting takes points within 2 sigma at 2 m (4.5 cm) as on the line: with the
    # thesis's 3 cm, walls came out jagged and so did ICP's reference (online position
    # error over office, rooms and furnished, 6 seeds: median RMS 0.091 -> 0.080 m, worst
    # maximum 0.55 -> 0.41 m; 0.15 m was worse, and the same for the RPLIDAR gained nothing)
    slam={"refine": {"inlier_threshold_m": 0.1}},
    odometry_noise={
        "trans_sigma_per_sqrt_m": 0.04,
        "lateral_sigma_per_sqrt_m": 0.02,
        "rot_sigma_per_sqrt_rad": 0.03,
        "rot_sigma_per_sqrt_m": 0.03,
        "scale_sigma": 0.01,
        "turn_scale_sigma": 0.02,
    },
)

TURTLEBOT4 = Profile(
    "turtlebot4",
    "TurtleBot4 (iRobot Create 3) with its RPLIDAR A1M8 lidar",
    # Slamtec RPLIDAR A1 datasheet (A1M8): 0.15-12 m, 360 degrees, 1 degree at the
    # typical 5.5 Hz (360 samples per scan), resolution under 1 % of the distance (taken
    # as one sigma). rplidar_ros publishes a beam with no return as +inf.
    lidar={
        "fov_rad": 2 * math.pi,
        "beams": 360,
        "range_min_m": 0.15,
        "range_max_m": 12.0,
        "rate_hz": 5.5,
        "noise_sigma_m": 0.005,
        "noise_sigma_per_m": 0.01,
        "dropout_prob": 0.01,
        "out_of_range": "inf",
        "rolling": True,
    },
    # Clearpath TurtleBot4 user manual: 0.31 m/s (safe mode), 1.90 rad/s, diameter
    # 341.77 mm (radius 0.171 m); accelerations as its Nav2 parameters
    base={
        "radius_m": 0.171,
        "max_linear_mps": 0.31,
        "max_angular_radps": 1.9,
        "max_linear_accel_mps2": 1.0,
        "max_angular_accel_radps2": 3.2,
    },
    # Create 3 wheel odometry fused with its gyro: mid-band
    odometry_noise={
        "trans_sigma_per_sqrt_m": 0.02,
        "lateral_sigma_per_sqrt_m": 0.01,
        "rot_sigma_per_sqrt_rad": 0.015,
        "rot_sigma_per_sqrt_m": 0.015,
        "scale_sigma": 0.005,
        "turn_scale_sigma": 0.01,
    },
)

HOKUYO = Profile(
    "hokuyo",
    "a Hokuyo UST-10LX class lidar (270 degrees, 10 m, 40 Hz) on the thesis's base",
    # Hokuyo UST-10LX specifications: 270 degrees at 0.25 degree (1,081 steps),
    # 0.06-10 m, 25 ms per scan (40 Hz), accuracy +-40 mm (taken as two sigma); no
    # return as +inf (REP 117)
    lidar={
        "fov_rad": math.radians(270.0),
        "beams": 1081,
        "range_min_m": 0.06,
        "range_max_m": 10.0,
        "rate_hz": 40.0,
        "noise_sigma_m": 0.02,
        "noise_sigma_per_m": 0.0,
        "dropout_prob": 0.005,
        "out_of_range": "inf",
        "rolling": True,
    },
    base=dict(THESIS.base),
    odometry_noise={
        "trans_sigma_per_sqrt_m": 0.02,
        "lateral_sigma_per_sqrt_m": 0.01,
        "rot_sigma_per_sqrt_rad": 0.015,
        "rot_sigma_per_sqrt_m": 0.01,
        "scale_sigma": 0.005,
        "turn_scale_sigma": 0.01,
    },
)

# the thesis's sensor and base on the TurtleBot3's wheels: how much of a profile's result
# comes from its odometry alone (maps that follow the pose graph are measured on it)
THESIS_NOISY_ODOMETRY = Profile(
    "thesis-noisy-odometry",
    "the thesis's sensor and base with the TurtleBot3's odometry noise",
    lidar=dict(THESIS.lidar),
    base=dict(THESIS.base),
    odometry_noise=dict(TURTLEBOT3.odometry_noise),
    # the wheel scale learnt (polyswarm.slam.odomscale): single-robot loop explorations with
    # this odometry, seeds 0-4, reached 99 % in 2 of 5 runs without, 4 of 5 with (8 of 10
    # over seeds 0-9; docs/exploration-log.md)
    slam={**THESIS.slam, "learn_odometry_scale": True},
)

# SLAM on a recording whose robot the user does not name (``polyswarm slam BAG``): real
# lidars lose beams in runs, so every scan is counted as evidence, and a beam without a
# return is trusted to 1 m. On neato-office-1 90 % of the no-return beams crossed at least
# 1.08 m of what other scans saw as free before the first wall they saw (neato-square
# 1.9 m, pioneer-hokuyo-corridor 2.95 m): the nearer figure, rounded down
RECORDING_SLAM = {"evidence": {"enabled": True}, "no_return_free_m": 1.0}

PROFILES: dict[str, Profile] = {
    p.name: p for p in (THESIS, TURTLEBOT3, TURTLEBOT4, HOKUYO, THESIS_NOISY_ODOMETRY)
}
DEFAULT_PROFILE = THESIS.name


def profile_names() -> tuple[str, ...]:
    return tuple(PROFILES)
