"""The last check before a velocity command leaves for a real base.

With ``output = "twist"`` polyswarm's own controller drives the robot through its
``cmd_vel``, with no costmap or collision monitor of the robot's stack in between.
``guard`` stops a forward (or backward) motion when any return lies in the robot's
way closer than ``stop_m`` beyond its body, and clamps the command to the configured
speed limits, whatever the controller decided.

    v, w = guard(v, w, returns_xy_robot_frame, radius_m=0.105, stop_m=0.05,
                 max_v_mps=0.22, max_w_radps=2.0)
"""

from __future__ import annotations

import numpy as np


def in_the_way(xy: np.ndarray, radius_m: float, stop_m: float, forward: bool) -> bool:
    """Whether any point (robot frame, x ahead) lies in the corridor the robot's body
    sweeps in the direction it drives, within ``stop_m`` of its front (or back)."""
    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    if not len(pts):
        return False
    x = pts[:, 0] if forward else -pts[:, 0]
    ahead = (x > 0.0) & (np.abs(pts[:, 1]) < radius_m)
    # the body's edge at lateral offset y is sqrt(r^2 - y^2) ahead of the centre
    edge = np.sqrt(np.maximum(radius_m**2 - pts[:, 1] ** 2, 0.0))
    return bool((ahead & (x - edge < stop_m)).any())


def guard(
    v_mps: float,
    w_radps: float,
    xy: np.ndarray,
    radius_m: float,
    stop_m: float,
    max_v_mps: float,
    max_w_radps: float,
) -> tuple[float, float]:
    """The command, clamped to the limits, with no translation towards a return closer
    than ``stop_m`` (turning in place stays allowed: a round robot sweeps nothing)."""
    v = float(np.clip(v_mps, -max_v_mps, max_v_mps))
    w = float(np.clip(w_radps, -max_w_radps, max_w_radps))
    if v != 0.0 and in_the_way(xy, radius_m, stop_m, forward=v > 0):
        v = 0.0
    return v, w
