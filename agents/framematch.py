"""One match of a waiting robot's map with the merged map (``agents.anchoring``): the
candidate frame ``match_maps`` finds, checked against the robots' sightings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.frames.estimate import MIN_SEEN
from polyswarm.frames.mapmatch import MapMatch, MatchError, fitting_rivals, match_maps, verdict_at
from polyswarm.frames.sighting import MIN_CONTRADICTIONS, Room, Track
from polyswarm.frames.sighting import contradicted_where as sighting_contradicted_where


def contradicted_where(theirs: dict[str, Track], mine: dict[str, Track], maps):
    """A function of the frame of ``mine``'s robots (their tracks by robot, in the frame
    of ``maps[1]``) in the frame of ``maps[0]``: the moments the sightings contradict it
    (``polyswarm.frames.sighting.contradicted_where``, over every pair of one of the other
    robots' tracks ``theirs`` and one of ``mine``), as ``_Audit.evidence``'s rows (the
    other robot, the robot of ``mine``, then the row); their number is what a match
    counts. Where the robots can stand in each map (``Room``) is
    built at the first call, in the thread that calls it."""
    rooms: list[Room] = []

    def where(frame: np.ndarray) -> list[tuple]:
        if not rooms:
            rooms.extend([Room(maps[0]), Room(maps[1])])
        return [
            (o, m, float(row[0]), int(row[1]), *(float(v) for v in row[2:]))
            for o, t in theirs.items()
            for m, u in mine.items()
            for row in sighting_contradicted_where(t, u, frame, (rooms[0], rooms[1]))
        ]

    return where


@dataclass(frozen=True)
class Matched:
    """What one match of a waiting robot's map found (``match_frame``)."""

    match: MapMatch | None  # None: no match (``why``)
    why: str = ""
    seen: int = 0  # places the robots saw each other at its pose
    # the moments that contradict the candidate frame it started with (``_Audit.evidence``'s
    # rows): at least ``MIN_CONTRADICTIONS`` and it is stale
    stale: tuple = ()


def match_frame(merged, own, where, seen_at, candidate=None, tracks=((), ())) -> Matched:
    """``match_maps`` of a robot's map on the merged map (its images unchecked: two more
    searches, three times the time, to tell what the sightings tell), and the places the
    robots saw each other at the pose it found (0 without sightings). ``where``: the
    moments the sightings contradict a frame (``contradicted_where``; None without
    sightings). ``candidate``: the frame the robot is being sent to meet the others by,
    checked against the sightings. ``tracks``: the merged map's robots' tracks and the
    waiting team's, whose paths spare walls (``match_maps``)."""
    contradicts = None if where is None else (lambda f: len(where(f)) >= MIN_CONTRADICTIONS)
    stale = tuple(where(candidate)) if candidate is not None and where is not None else ()
    try:
        theirs, mine = tracks
        a_paths = [p for t in theirs for p in t.paths()]
        b_paths = [p for t in mine for p in t.paths()]
        m = match_maps(merged, own, contradicts, images=False, a_paths=a_paths, b_paths=b_paths)
    except (MatchError, PolyswarmError) as e:
        return Matched(None, str(e), stale=stale)
    if seen_at is None or not m.proposed:
        return Matched(m, stale=stale)
    seen = seen_at(m.pose)
    if seen < MIN_SEEN:
        # the maps fit an image as well (a symmetric building): if the robots saw each
        # other where an image puts them, that image is the one to propose (the loop,
        # seed 3: an image scored best for 9 matches while the truth, a fitting rival,
        # was seen at once when it came first)
        for pose in fitting_rivals(m):
            n = seen_at(pose)
            if n > seen:
                m, seen = verdict_at(m, pose), n
    return Matched(m, seen=seen, stale=stale)
