"""Refinement speed on keyframes of the maze, and whether two versions agree exactly.

    python examples/refine_timing.py [OUT.pkl [REFERENCE.pkl]]

Drives the simulated robot along the first 300 s of its maze coverage route, makes a
keyframe polygon of every tenth scan at the true pose and times ``refine_polygon`` on
them. With OUT, the refined polygons are saved; with REFERENCE too, they are compared
with a saved run (``PYTHONPATH=/other/checkout`` for the other version's).
"""

import math
import pickle
import sys
import time

import numpy as np

from polyswarm.config import Config
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.refine import refine_polygon
from polyswarm.slam.scan import scan_to_points
from sim import Simulation, load_world
from sim.route import PurePursuit, coverage_route

cfg = Config()
world = load_world("data:maze")
route = coverage_route(world)
start = (*route[0], math.atan2(*(route[1] - route[0])[::-1]))
polys = []
with Simulation(world, cfg.sim, 1, start_poses=[start]) as sim:
    follower = PurePursuit(route, speed=1.0)
    n = 0
    while sim.time < 300.0:
        for e in sim.step():
            if n % 10 == 0:
                pts = scan_to_points(
                    e.scan, cfg.slam.frontier_range_m, no_return_free_m=cfg.slam.no_return_free_m
                )
                polys.append(
                    keyframe_polygon(
                        pts, e.true_pose, cfg.slam.obstacle_max_gap_m, cfg.slam.obstacle_gap_beams
                    )
                )
            n += 1
        sim.set_cmd(0, *follower.command(sim.robots[0].pose))
t0 = time.perf_counter()
outs = [refine_polygon(p, cfg.slam.refine) for p in polys]
dt = time.perf_counter() - t0
print(f"{len(polys)} keyframes, {1e3 * dt / len(polys):.2f} ms each")
if len(sys.argv) > 1:
    with open(sys.argv[1], "wb") as f:
        pickle.dump([(o[0].shell.xy, o[0].shell.types, o[1]) for o in outs], f)
if len(sys.argv) > 2:
    with open(sys.argv[2], "rb") as f:
        ref = pickle.load(f)
    mine = [(o[0].shell.xy, o[0].shell.types, o[1]) for o in outs]
    same = len(ref) == len(mine) and all(
        np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
        for a, b in zip(ref, mine, strict=True)
    )
    print("identical to reference:", same)
