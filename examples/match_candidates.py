"""Where a known frame stands among a waiting robot's match candidates, match by match.

Traces why a robot at unknown starts is merged late: was its true frame among the
search's candidates, how well did the maps fit there, did the robots see each other
there? The coordinator does not record its matches' inputs; for a trace, make it pickle
them with this change to ``agents/anchoring.py`` (not kept in the repository: it writes
a file per match), and run a launch with ``PS_DUMP=DIR`` set:

    # in Anchoring._evidence, after ``maps = ...``:   self._dump = (theirs, mine)
    # in the matching step, after ``where, seen_at, tracks = self._evidence(...)``:
    if os.environ.get("PS_DUMP"):
        os.makedirs(os.environ["PS_DUMP"], exist_ok=True)
        with open(f"{os.environ['PS_DUMP']}/{rid}-{now_s:07.1f}.pkl", "wb") as fh:
            pickle.dump((now_s, rid, main.merged, own, getattr(self, "_dump", None)), fh)

    python examples/match_candidates.py [--json] [--peaks N] [--ahead N] DIR ROBOT X_M,Y_M,THETA_DEG

``X_M,Y_M,THETA_DEG``: the robot's true frame in the merged map's (its committed frame,
from the coordinator's log, when that was right). Per match: the rank of the first
search candidate within 1.5 m and 5 deg of it among the coarse candidates
(``polyswarm.frames.mapsearch``, ``PEAKS`` per heading, or ``--peaks``) and among those the
match refines; how many coarse candidates ahead of it (at most ``--ahead``, 300) the
sightings contradict; the maps' fit
at the frame after ICP; the places the robots saw each other where it puts them.
"""

from __future__ import annotations

import glob
import json
import math
import pickle
import sys

import numpy as np

from agents.anchoring import MIN_CONTRADICTIONS, _contradicted_where
from polyswarm.frames import mapmatch as mm
from polyswarm.frames import mapsearch as ms
from polyswarm.frames.sighting import distinct_places, mutual_seen
from polyswarm.se2 import wrap

AHEAD_CHECKED = 300  # coarse candidates ahead of the truth checked against the sightings


def _near(pose, truth, d_m: float) -> bool:
    return bool(np.hypot(*(pose[:2] - truth[:2])) < d_m and abs(wrap(pose[2] - truth[2])) < 0.09)


def trace(path: str, truth: np.ndarray, ahead_checked: int = AHEAD_CHECKED) -> dict:
    with open(path, "rb") as fh:
        now, _, merged, own, dump = pickle.load(fh)
    theirs, mine = dump if dump else ({}, {})
    va = mm._view(merged, [p for t in theirs.values() for p in t.paths()])
    vb = mm._view(own, [p for t in mine.values() for p in t.paths()])
    # the coarse list as ``mapsearch.search`` builds it, kept whole
    res = ms.RESOLUTION_M
    b_clear = (np.argwhere(vb.clear > 0) + 0.5) * res + vb.lo
    centre = vb.walls.mean(axis=0)
    pts = np.concatenate([vb.walls, b_clear]) - centre
    radius = float(np.hypot(pts[:, 0], pts[:, 1]).max())
    nb, off = int(np.ceil(2 * radius / res)) + 2, np.full(2, radius + res)
    heads = np.arange(-math.pi, math.pi, ms.HEADING_STEP_RAD)
    a_ij = np.floor((va.walls - va.lo) / res).astype(int)
    coarse = ms._coarse(va, vb, a_ij, centre, off, nb, heads)

    def pose_of(h, d) -> np.ndarray:
        t = va.lo + ms.COARSE * d * res + off - ms._rotation(heads[h]) @ centre
        return np.array([t[0], t[1], heads[h]])

    poses = [pose_of(h, d) for _, h, d in coarse]
    rank = next((k for k, p in enumerate(poses) if _near(p, truth, 1.5)), None)
    where = _contradicted_where(theirs, mine, (merged, own)) if theirs and mine else None
    ahead = poses[: min(ahead_checked, len(poses) if rank is None else rank)]
    contradicted = (
        sum(len(where(p)) >= MIN_CONTRADICTIONS for p in ahead) if where is not None else 0
    )
    final = ms.search(va, vb)
    fit = mm._evidence(va, vb, mm._icp(va, mm.wall_tree(va), vb, truth))
    seen = [mutual_seen(t, u, truth, (merged, own)) for t in theirs.values() for u in mine.values()]
    return {
        "t_s": float(now),
        "coarse_candidates": len(poses),
        "truth_coarse_rank": rank,
        "truth_refined_rank": next(
            (k for k, (_, p) in enumerate(final) if _near(p, truth, 1.0)), None
        ),
        "ahead_checked": len(ahead),
        "ahead_contradicted": int(contradicted),
        "truth_overlap_m2": fit["overlap_m2"],
        "truth_agreeing_wall_m": fit["agreeing_wall_m"],
        "truth_conflict_share": fit["conflict_share"],
        "truth_seen_places": distinct_places(np.vstack(seen)) if seen else 0,
    }


def main(args: list[str]) -> None:
    opts: dict[str, str] = {}
    while args and args[0].startswith("--"):
        flag = args.pop(0)
        opts[flag] = "" if flag == "--json" else args.pop(0)
    folder, robot, frame = args
    if "--peaks" in opts:  # candidates kept per heading (the search keeps PEAKS)
        ms.PEAKS = int(opts["--peaks"])
    x, y, th = (float(v) for v in frame.split(","))
    truth = np.array([x, y, math.radians(th)])
    ahead = int(opts.get("--ahead", AHEAD_CHECKED))
    rows = [trace(p, truth, ahead) for p in sorted(glob.glob(f"{folder}/{robot}-*.pkl"))]
    as_json = "--json" in opts
    if as_json:
        print(json.dumps(rows, indent=1))
        return
    for r in rows:
        print(
            f"{r['t_s']:6.1f} s: truth #{r['truth_coarse_rank']} of {r['coarse_candidates']} "
            f"coarse (ahead: {r['ahead_contradicted']}/{r['ahead_checked']} contradicted), "
            f"#{r['truth_refined_rank']} refined; there overlap {r['truth_overlap_m2']:.0f} m2, "
            f"agreeing wall {r['truth_agreeing_wall_m']:.0f} m, conflicts "
            f"{r['truth_conflict_share']:.1%}, seen in {r['truth_seen_places']} places"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
