"""Occupancy grids.

* ``occupancy``: ``OccupancyGrid`` with nav_msgs/OccupancyGrid semantics;
* ``convert``: occupancy grid <-> PolyMap (thesis Algorithm 1);
* ``counting``: the grid gmapping builds (the bandwidth baseline);
* ``logodds``: the log-odds grid of the same scans at the same poses (the reference a
  map built from real scans is judged against).
"""
