"""A PolyMap against its world's ground truth: what the IoU leaves out.

    python examples/map_vs_truth.py runs/<launch>/map.polymap office

Explored space outside the true free space (mostly inside walls), true free space not
mapped, and the IoU of the two.
"""

from __future__ import annotations

import sys

import shapely

from protocols.files import read_polymap
from sim.world import load_world


def main(polymap: str, world: str) -> None:
    free = read_polymap(polymap).explored_region()
    truth = load_world(world).free
    outside = shapely.area(shapely.difference(free, truth))
    missed = shapely.area(shapely.difference(truth, free))
    both = shapely.area(shapely.intersection(free, truth))
    print(
        f"IoU {both / (both + outside + missed):.3f}; mapped outside the true free space "
        f"{outside:.1f} m2, true free space not mapped {missed:.1f} m2 "
        f"(of {shapely.area(truth):.1f} m2)"
    )


if __name__ == "__main__":
    main(*sys.argv[1:])
