"""Exploration.

* ``frontiers``: frontier vectors of a map;
* ``targets``: frontier targets for a robot's sensor, and what they are worth;
* ``assign``: assigning targets to robots (Hungarian, greedy, nearest).
"""
