"""How far may a robot be and still count as sighted? Right and wrong frames, by range cap.

A frame of a waiting robot is committed once the robots saw each other in
``MIN_SEEN`` places where it puts them (``polyswarm.sighting``). This re-records
``bench merge``'s explorations (``polyswarm.benchmarks.merge._snapshots``: the same
worlds, seeds and robots, deterministic) and, at every moment and pose that
``bench merge`` stored in a result file, counts the places again with sightings
farther than each cap left out. Poses are scored by the result file's ground truth
(``found.wrong``: more than 1 m or 5 degrees off).

    .venv/bin/python examples/sighting_range.py docs/results/merge-seen.json \\
        office:0 rooms:0 loop:1 loop:3 cross:0 cross:2 maze:1 maze:3 \\
        --out docs/results/merge-sight-range.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from polyswarm import sighting
from polyswarm.benchmarks.merge import _snapshots
from polyswarm.benchmarks.results import machine_meta
from polyswarm.config import Config, with_profile
from polyswarm.mapmatch import MIN_SEEN

CAPS_M = (math.inf, 20.0, 15.0, 10.0, 8.0, 6.0)  # range caps tried, metres


def _rows(result: dict, world: str, seed: int):
    for pair in result["pairs"]:
        if pair["world"] == world and pair["seed"] == seed:
            k = int(pair["robot"][1:]) - 1
            for row in pair["rows"]:
                if "pose" in row["ours"]:
                    yield k, row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("result", help="a bench merge result file with per-moment poses")
    ap.add_argument("runs", nargs="+", help="world:seed runs to record again")
    ap.add_argument("--out", required=True, help="where to write the JSON result")
    args = ap.parse_args()
    with open(args.result) as f:
        result = json.load(f)
    profile = result["profiles"][0]
    cfg = with_profile(Config(), profile)
    counts = {str(c): {"right": [], "wrong": []} for c in CAPS_M}
    reproduced = total = 0
    for spec in args.runs:
        world, seed = spec.rsplit(":", 1)
        t0 = time.perf_counter()
        own, _starts, tracks = _snapshots(world, int(seed), result["robots"], cfg)
        maps_at = {round(t, 1): maps for t, maps in own}
        for k, row in _rows(result, world, int(seed)):
            maps = maps_at.get(round(row["t_s"], 1))
            if maps is None:
                continue
            a, b = maps[0], maps[k]
            mine, theirs = tracks[0].until(row["t_s"]), tracks[k].until(row["t_s"])
            pose = np.array(row["ours"]["pose"])
            kind = "wrong" if row["ours"]["found"]["wrong"] else "right"
            for cap in CAPS_M:
                seen = sighting.mutual_seen(mine, theirs, pose, (a, b), max_range_m=cap)
                n = sighting.distinct_places(seen)
                counts[str(cap)][kind].append(n)
                if cap == math.inf:
                    total += 1
                    reproduced += n == row["ours"]["seen"]
        print(f"{spec}: recorded and counted in {time.perf_counter() - t0:.0f} s")
    need = MIN_SEEN
    table = {
        cap: {
            "right_poses": len(c["right"]),
            "right_seen_enough": sum(n >= need for n in c["right"]),
            "wrong_poses": len(c["wrong"]),
            "wrong_seen_at_all": sum(n >= 1 for n in c["wrong"]),
            "wrong_seen_enough": sum(n >= need for n in c["wrong"]),
            "wrong_seen_max": max(c["wrong"], default=0),
        }
        for cap, c in counts.items()
    }
    out = {
        "source": args.result,
        "runs": args.runs,
        "profile": profile,
        "places_needed": need,
        "moments_reproduced": reproduced,
        "moments": total,
        "by_cap_m": table,
        "meta": machine_meta() | {"command": " ".join(["python", *sys.argv])},
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    print(f"uncapped counts equal the stored ones at {reproduced} of {total} moments")
    for cap, s in table.items():
        print(
            f"cap {cap} m: right poses seen in {need}+ places {s['right_seen_enough']} of "
            f"{s['right_poses']}; wrong seen at all {s['wrong_seen_at_all']}, in {need}+ "
            f"places {s['wrong_seen_enough']} of {s['wrong_poses']}"
        )


if __name__ == "__main__":
    main()
