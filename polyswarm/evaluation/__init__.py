"""Metrics (pure functions, no I/O).

* ``trajectory``: ATE, RPE, largest errors;
* ``maps``: maps against ground truth or another map (IoU, wall distance, ghosts);
* ``coverage``: what an exploration must cover, and when it got there;
* ``grid_scores``: a map built from real scans against the grid of the same scans.
"""
