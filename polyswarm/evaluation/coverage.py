"""Coverage: what a complete exploration must have explored, and when it got there
(pure functions, no I/O).

time_to_coverage(curve, 0.99)      first time a coverage curve reaches a fraction (t99)
reachable_free(free, radius, starts, tolerance)   the space exploration must cover
"""

from __future__ import annotations

import shapely


def time_to_coverage(curve, fraction: float) -> float | None:
    """The first time (s) of ``curve`` ((time s, covered fraction) pairs in time order)
    at which the covered fraction is at least ``fraction``; None if it never is."""
    return next((t for t, c in curve if c >= fraction), None)


# walls are mostly seen from a couple of metres indoors: the lidar's noise there sets how
# far inside the true wall a correct map's boundary may lie
TYPICAL_WALL_RANGE_M = 2.0


def coverage_tolerance(noise_sigma_m: float, noise_sigma_per_m: float, resolution_m: float = 0.0):
    """Width (m) of the band along obstacles that coverage does not count: two standard
    deviations of the lidar's range noise at ``TYPICAL_WALL_RANGE_M``, or the ground
    truth's own resolution (a map_server map's pixel) if that is coarser."""
    sigma = noise_sigma_m + noise_sigma_per_m * TYPICAL_WALL_RANGE_M
    return max(2.0 * sigma, resolution_m)


def reachable_free(
    free: shapely.Geometry, radius_m: float, starts_xy, tolerance_m: float = 0.0
) -> shapely.Geometry:
    """The free space a robot of ``radius_m`` can sweep from its start: its disc's centre
    moves through ``free`` shrunk by the radius, in the parts holding a start; the disc
    covers that grown back by the radius (the reference planner's definition). A band of
    ``tolerance_m`` along every boundary is left out: a correct map's walls lie within the
    lidar's noise of the true ones, on either side."""
    centres = shapely.buffer(free, -radius_m, quad_segs=4)
    pts = [shapely.Point(float(x), float(y)) for x, y, *_ in starts_xy]
    parts = [p for p in shapely.get_parts(centres) if any(p.distance(q) < radius_m for q in pts)]
    if not parts:
        return shapely.Polygon()
    swept = shapely.intersection(shapely.buffer(shapely.union_all(parts), radius_m), free)
    return shapely.buffer(swept, -tolerance_m, quad_segs=4) if tolerance_m > 0 else swept
