"""What a sighting rule changed in whole launches: matches scored by ground truth.

The coordinator logs every match of a waiting robot's map with the places the robots
saw each other where it puts them, by the rule it decides with and, when that differs,
by another rule: "seen 2 time(s) (4 by the former rule: within 15 m, no arc)" (the
sector's arc test, ``polyswarm.frames.sighting.ARC_CLEAR_M``, against the 15 m cap before
it; code 82dfaac to 8814950); logs of the 15 m cap's code say "(4 counting sightings
beyond 15 m)" (the cap against none). Logs of later code carry the arc rule alone: the
other rule's counts then read as equal. This reads run folders of ``polyswarm bench
explore --unknown-start`` (their ``config.toml`` holds the true starts; nobody told
the robots) and scores each proposed pose against the truth: right within 1 m and 5
degrees, else wrong. It counts the matches seen in ``MIN_SEEN`` places by either rule,
right and wrong.

    .venv/bin/python examples/launch_sightings.py /tmp/us2/*unknown* --out result.json
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import tomllib
from pathlib import Path

import numpy as np

from polyswarm.benchmarks.results import machine_meta
from polyswarm.frames.mapmatch import MIN_SEEN, frame_error
from polyswarm.se2 import compose, inverse

RIGHT_M, RIGHT_RAD = 1.0, math.radians(5.0)  # bench merge's WRONG_M, WRONG_RAD
_MATCH = re.compile(
    r"map of (r\d+) against the merged map \(match (\d+)\): pose \(([-\d.]+) m, ([-\d.]+) m, "
    r"([-\d.]+) deg\).*?, seen (\d+) time\(s\)"
    r"(?: \((\d+) (counting sightings beyond \d+ m|by the former rule: [^)]*)\))?"
)

_UNDONE = re.compile(r"robot (r\d+): \d+ moments since its merge contradict .*?merge undone")


def _log_records(path: Path) -> list[str]:
    """The log's records, rich's wrapped continuation lines joined back on (runs of
    spaces made one: the wrapping pads lines)."""
    out: list[str] = []
    for line in path.read_text(errors="replace").splitlines():
        if line.startswith(" " * 10) and out:
            out[-1] += " " + line.strip()
        else:
            out.append(line)
    return [re.sub(r"\s+", " ", r) for r in out]


def run_matches(folder: Path) -> list[dict]:
    """Every logged match of a run with its sightings and its truth. Matches of a robot
    whose merge was undone are left out from then on: it speaks in the frame it was
    anchored in, not its start's, so its start says nothing of them."""
    cfg = tomllib.loads((folder / "config.toml").read_text())
    starts = np.array(cfg["sim"]["start_poses"], dtype=float)
    rows = []
    undone: set[str] = set()
    for record in _log_records(folder / "logs" / "coordinator.log"):
        undone |= set(_UNDONE.findall(record))
        for m in _MATCH.finditer(record):
            rid, k = m.group(1), int(m.group(2))
            if rid in undone:
                continue
            pose = np.array([float(m.group(3)), float(m.group(4)), math.radians(float(m.group(5)))])
            i = int(rid[1:]) - 1
            truth = compose(inverse(starts[0]), starts[i])
            e_m, e_rad = frame_error(pose, truth)
            seen = int(m.group(6))
            rows.append(
                {
                    "run": folder.name,
                    "robot": rid,
                    "match": k,
                    "right": e_m <= RIGHT_M and e_rad <= RIGHT_RAD,
                    "seen": seen,
                    "seen_other_rule": int(m.group(7)) if m.group(7) else seen,
                    "other_rule": m.group(8),
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run folders of bench explore")
    ap.add_argument("--out", help="write the counts (JSON) here")
    args = ap.parse_args()
    rows = [r for f in args.runs for r in run_matches(f)]
    summary = {}
    for kind, right in (("right", True), ("wrong", False)):
        sel = [r for r in rows if r["right"] == right]
        summary[kind] = {
            "matches": len(sel),
            "seen_enough": sum(r["seen"] >= MIN_SEEN for r in sel),
            "seen_enough_by_the_other_rule": sum(r["seen_other_rule"] >= MIN_SEEN for r in sel),
            "rules_differ": sum(r["seen"] != r["seen_other_rule"] for r in sel),
        }
    other = sorted({r["other_rule"] for r in rows if r["other_rule"]})
    out = {
        "runs": [f.name for f in args.runs],
        "places_needed": MIN_SEEN,
        "other_rule": other,
        **summary,
    }
    print(json.dumps(out, indent=1))
    if args.out:
        meta = machine_meta() | {"command": " ".join(["python", *sys.argv])}
        Path(args.out).write_text(json.dumps({**out, "matches": rows, "meta": meta}, indent=1))


if __name__ == "__main__":
    main()
