"""Where robots' frames lie in each other's.

* ``mapmatch``, ``mapsearch``: maps matched without start poses;
* ``meeting``, ``sighting``: robots that see each other confirm a frame;
* ``jointgraph``: one pose graph over all robots' keyframes.
"""
