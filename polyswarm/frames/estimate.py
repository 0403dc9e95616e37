"""A frame committed on evidence: successive map matches that agree, and the robots seen
where the frame puts them (``FrameEstimate``)."""

from __future__ import annotations

import math

import numpy as np

from polyswarm.frames.mapmatch import MapMatch
from polyswarm.frames.mapsearch import close as _close

AGREE_M, AGREE_RAD = 0.3, math.radians(3.0)  # two matches within this are the same frame
AGREE_MATCHES = 2  # matches in a row that must propose a frame before it is committed
REVISE_MATCHES = 3  # matches in a row that propose another frame (robots seen): revise it
# the robots must have seen each other in this many places where the frame puts them
# (``polyswarm.frames.sighting.distinct_places``) before it is committed: in a building that looks
# the same after a quarter turn the maps fit a wrong image as well as the truth, or better
# when SLAM drift bends one map (bench merge, 5 worlds x 5 seeds: at the 43 wrong poses
# accepted the robots were seen in 0-2 places, at 55 of 136 right ones in 3-13). Nothing
# else commits a frame: standing 60 s uncontradicted (an earlier rule, for robots that
# cannot reach each other) committed 3 frames unseen in 16 launches, 2 of them 30 m and
# 90 deg off (loop and cross seed 2, explore-unknown-start-rv-seeds2-4.json)
MIN_SEEN = 3


class FrameEstimate:
    """One robot's frame in the shared one, from successive ``match_maps`` results and
    the robots' sightings of each other at them.

    One match is not trusted: the frame is committed when ``AGREE_MATCHES`` matches in a
    row (made as the maps grew) propose it and the robots saw each other in ``MIN_SEEN``
    places where the last one puts them. A match proposes its pose when it is accepted or
    refused only on what sightings settle (``MapMatch.proposed``: the maps also fit at
    rivals or symmetric images, or conflict slightly): the sightings single the truth
    out of those as they do out of a wrong accepted pose.
    Silence commits nothing: robots that never see each other are not merged
    (``agents.anchoring`` sends them to meet). Once committed, proposals that contradict
    it are counted; ``REVISE_MATCHES`` in a row that agree among themselves, the robots
    seen at the last, replace it (a wrong merge undone). Other refusals change nothing.

    ``candidate`` is the frame the latest proposal puts forward while none is committed:
    where to look for the other robots (``agents.anchoring``)."""

    def __init__(self) -> None:
        self.pose: np.ndarray | None = None  # the committed frame
        self.run: list[np.ndarray] = []  # the latest proposals that agree
        self.candidate: np.ndarray | None = None
        self.contradictions = 0
        self.revisions = 0

    def forget_candidate(self) -> None:
        """The candidate is contradicted (the robots would have seen each other there):
        none until the next proposal."""
        self.candidate = None

    def add(self, m: MapMatch, seen: int = 0) -> np.ndarray | None:
        """The committed frame after ``m``, at whose pose the robots saw each other in
        ``seen`` places."""
        if not m.proposed:
            return self.pose
        sighted = seen >= MIN_SEEN
        self.candidate = m.pose
        if self.run and not _close(m.pose, self.run[-1], AGREE_M, AGREE_RAD):
            self.run = []
        self.run.append(m.pose)
        if self.pose is None:
            if len(self.run) >= AGREE_MATCHES and sighted:
                self.pose = self.run[-1]
        elif _close(m.pose, self.pose, AGREE_M, AGREE_RAD):
            self.pose = m.pose  # the latest agreeing estimate (the maps grew)
        else:
            self.contradictions += 1
            if len(self.run) >= REVISE_MATCHES and sighted:
                self.pose, self.revisions = self.run[-1], self.revisions + 1
        return self.pose
