"""When does a return count as a sighting of a robot? Right and wrong frames, by rule.

A frame of a waiting robot is committed once the robots saw each other in
``MIN_SEEN`` places where it puts them (``polyswarm.frames.sighting``). This re-records
``bench merge``'s explorations (``polyswarm.benchmarks.merge._snapshots``: the same
worlds, seeds and robots, deterministic) and, at every moment and pose that
``bench merge`` stored in a result file, counts the places again by each rule of
``RULES``: a range cap, and the sector's centre or its whole arc clear of walls. Poses
are scored by the result file's ground truth (``found.wrong``: more than 1 m or 5
degrees off).

    .venv/bin/python examples/sighting_range.py docs/results/merge-seen.json \\
        office:0 rooms:0 loop:1 loop:3 cross:0 cross:2 maze:1 maze:3 \\
        --out docs/results/merge-sight-arc.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from polyswarm.benchmarks.merge import _snapshots
from polyswarm.benchmarks.results import machine_meta
from polyswarm.config import Config, with_profile
from polyswarm.frames import sighting
from polyswarm.frames.mapmatch import MIN_SEEN

# the sighting rules tried (``polyswarm.frames.sighting.seen_where``): a range cap in metres, and
# whether the sector's whole arc must lie clear of walls or only its centre
RULES = {
    "centre, any range": {"max_range_m": math.inf, "arc": False},
    "centre, within 20 m": {"max_range_m": 20.0, "arc": False},
    "centre, within 15 m (the former rule)": {"max_range_m": 15.0, "arc": False},
    "centre, within 10 m": {"max_range_m": 10.0, "arc": False},
    "arc, any range (the rule now)": {"max_range_m": math.inf, "arc": True},
    "arc, within 15 m": {"max_range_m": 15.0, "arc": True},
}
REPRODUCED = "centre, any range"  # the rule bench merge stored its counts with


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
    counts = {name: {"right": [], "wrong": []} for name in RULES}
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
            for name, rule in RULES.items():
                seen = sighting.mutual_seen(mine, theirs, pose, (a, b), **rule)
                n = sighting.distinct_places(seen)
                counts[name][kind].append(n)
                if name == REPRODUCED:
                    total += 1
                    reproduced += n == row["ours"]["seen"]
        print(f"{spec}: recorded and counted in {time.perf_counter() - t0:.0f} s")
    need = MIN_SEEN
    table = {
        name: {
            "right_poses": len(c["right"]),
            "right_seen_enough": sum(n >= need for n in c["right"]),
            "wrong_poses": len(c["wrong"]),
            "wrong_seen_at_all": sum(n >= 1 for n in c["wrong"]),
            "wrong_seen_enough": sum(n >= need for n in c["wrong"]),
            "wrong_seen_max": max(c["wrong"], default=0),
        }
        for name, c in counts.items()
    }
    out = {
        "source": args.result,
        "runs": args.runs,
        "profile": profile,
        "places_needed": need,
        "moments_reproduced": reproduced,
        "moments": total,
        "by_rule": table,
        "meta": machine_meta() | {"command": " ".join(["python", *sys.argv])},
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    print(f"{REPRODUCED}: counts equal the stored ones at {reproduced} of {total} moments")
    for name, s in table.items():
        print(
            f"{name}: right poses seen in {need}+ places {s['right_seen_enough']} of "
            f"{s['right_poses']}; wrong seen at all {s['wrong_seen_at_all']}, in {need}+ "
            f"places {s['wrong_seen_enough']} of {s['wrong_poses']}"
        )


if __name__ == "__main__":
    main()
