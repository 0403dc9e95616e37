"""PolySLAM (thesis chapter 3): one module per stage, and the loop over them.

* ``scan``: a LaserScan to points (beam classes, de-skewing);
* ``keyframe``: the keyframe polygon; ``refine``: line fitting; ``trim``: what a
  keyframe adds;
* ``icp``, ``submap``, ``loopsearch``: alignment against nearby keyframes;
* ``posegraph``, ``odometry``, ``odomscale``: the pose graph and the odometry;
* ``follow``: the map follows the pose graph (the atlas of merged keyframes);
* ``polyslam``: ``PolySlam``, the per-scan step.
"""
