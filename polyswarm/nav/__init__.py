"""Navigation on a PolyMap (thesis chapter 4).

* ``navgraph``: the graph over the map's convex pieces;
* ``planner``: A* over it and funnel paths;
* ``control``: the local controller that follows a path around what the lidar sees;
* ``gridplan``: the grid planner that ``polyswarm bench nav`` compares with.
"""
