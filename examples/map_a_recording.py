"""PolySLAM on a real recording through the library: the map, its picture, its size.

    python examples/map_a_recording.py ../shared/data/bags/neato-square.bag [OUT.png]

The same as ``polyswarm slam BAG -o DIR`` without the command: the bag is read, the
scan topic, the lidar mount and the driver's no-return value are found, and PolySLAM
runs with the settings for low-cost lidars.
"""

from __future__ import annotations

import sys

from polyswarm.config import Config
from polyswarm.io.export import export_map
from polyswarm.runners.slam import run_bag
from protocols.mapcodec import encode_map


def main(bag: str, out: str = "recording.png") -> None:
    run, _ = run_bag(bag, Config())
    pmap = run.map
    print(
        f"{bag}: {len(run.stamps)} scans, {run.slam.keyframes} keyframes, "
        f"{pmap.explored_region().area:.1f} m2 explored, "
        f"the map is {len(encode_map(pmap)):,} bytes"
    )
    export_map(pmap, out)
    print(f"map drawn to {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
