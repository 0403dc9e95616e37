"""The simulator: pybullet worlds, differential-drive robots, 2D lidar and odometry.

Independent of ``agents`` and ``protocols``; the ``polyswarm sim`` command wires it to
Zenoh. Headless (pybullet DIRECT) unless asked for a GUI.
"""

from sim.simulation import (
    CollisionEvent,
    Robot,
    ScanEvent,
    Simulation,
)
from sim.starts import scattered_start_poses, spread_start_poses
from sim.world import PROCEDURAL, World, load_world, procedural_world, world_from_grid

__all__ = [
    "PROCEDURAL",
    "CollisionEvent",
    "Robot",
    "ScanEvent",
    "Simulation",
    "World",
    "load_world",
    "procedural_world",
    "scattered_start_poses",
    "spread_start_poses",
    "world_from_grid",
]
