"""Audits of the frames of robots merged on a frame this coordinator found
(``agents.anchoring``): every ``AUDIT_PERIOD_S`` what came since the hand-over (the
robots' sightings, and its map against the maps of robots whose frames are not in doubt)
is weighed; ``UNDO_CONTRADICTIONS`` moments or ``UNDO_AUDITS`` conflicting audits in a row
undo the merge (``Anchoring._undo``)."""

from __future__ import annotations

import logging
import math
from concurrent.futures import Future
from dataclasses import dataclass, field

import numpy as np

from agents.framematch import contradicted_where
from polyswarm.frames.mapmatch import MIN_OVERLAP_M2, fit_at
from polyswarm.frames.sighting import MIN_CONTRADICTIONS
from protocols.messages import Anchor

log = logging.getLogger(__name__)

AUDIT_PERIOD_S = 10.0  # simulated seconds between audits of one merged robot's frame
# moments since the hand-over that contradict a merged robot's frame before the merge is
# undone: twice what leaves a candidate frame out (a frame the robots saw each other at
# in three places is withdrawn on clearer evidence than a candidate is passed over on)
UNDO_CONTRADICTIONS = 2 * MIN_CONTRADICTIONS
# of the walls a merged robot's map shares with the maps merged before it, the share in
# their clear space that undoes the merge, in UNDO_AUDITS audits in a row: right frames
# conflict 0.1-0.2 % on the thesis sensor and 1-8 % on the TurtleBot3 (doubled
# walls); a frame 2.2 m and 20 deg off, 62-69 % (office launch, seed 1)
UNDO_CONFLICT_SHARE = 0.25
UNDO_AUDITS = 2
UNDO_EVIDENCE_LOGGED = 10  # contradicting moments logged with an undo


@dataclass
class Audit:
    """A merged robot whose frame this coordinator found: checked on later sightings."""

    frame: int  # the anchor its poses name
    since_s: float  # handed over then: sightings since are the audit's evidence
    last_s: float = -math.inf
    running: Future | None = None
    # the latest audit's moments against the frame: (other robot, time s, viewer 0 (the
    # other) or 1 (this one), the viewer's x, y, where the frame put the one not seen
    # x, y), metres, shared frame
    evidence: list[tuple] = field(default_factory=list)
    conflicting: int = 0  # audits in a row whose maps conflicted


class Audits:
    """The audits of an ``Anchoring`` (a mixin: it keeps ``audits``, ``tracks`` and
    ``_audit_pool``, and undoes a merge with ``_undo``)."""

    def _audit(self, main, now_s: float) -> list[tuple[str, Anchor]]:
        """Take finished audits (undoing a merge the evidence contradicts); start due ones."""
        out = []
        for rid, a in list(self.audits.items()):
            if a.running is not None and a.running.done():
                try:
                    a.evidence, share, overlap_m2 = a.running.result()
                except Exception:  # a failed audit must not stop the coordinator: retried
                    log.exception("auditing the frame of %s failed", rid)
                else:
                    clash = share >= UNDO_CONFLICT_SHARE and overlap_m2 >= MIN_OVERLAP_M2
                    a.conflicting = a.conflicting + 1 if clash else 0
                    log.info(
                        "frame of %s audited: %d moments against it; %.1f %% of the walls "
                        "shared with earlier maps (%.0f m2) in their clear space",
                        rid,
                        len(a.evidence),
                        100 * share,
                        overlap_m2,
                    )
                a.running = None
                if len(a.evidence) >= UNDO_CONTRADICTIONS or a.conflicting >= UNDO_AUDITS:
                    out.append((rid, self._undo(rid, main, now_s)))
                    continue
            if a.running is None and now_s - a.last_s >= AUDIT_PERIOD_S:
                a.last_s = now_s
                audit = self._audit_evidence(rid, a, main)
                if audit is not None:
                    a.running = self._audit_pool.submit(audit)
        return out

    def _audit_evidence(self, rid: str, a: Audit, main):
        """A function measuring what came since ``rid``'s hand-over against its frame:
        (moments the robots' sightings contradict it, the share of the walls its map
        shares with the maps it is held against that stand in their clear space, the
        explored area shared); None while its map is not in.

        The maps it is held against: those of the robots whose frames nobody audits
        (starts given, the first robot) where they share ``MIN_OVERLAP_M2``; else those
        of the robots merged before it. (Held against every earlier map, a right frame
        met 22 % conflicts from a wrong one merged 2 s before it, office launch, seed 1.)"""
        info = main.robots.get(rid)
        if info is None or info.map is None:
            return None
        earlier = [
            (o not in self.audits, other.map)
            for o, other in main.robots.items()
            if o != rid
            and other.map is not None
            and (o not in self.audits or self.audits[o].since_s < a.since_s)
        ]
        mine = self.tracks.get(rid)
        if mine is not None:
            mine = mine.since(max(a.since_s, info.corrected_s))
        theirs = {
            o: self.tracks[o].since(max(a.since_s, other.corrected_s))
            for o, other in main.robots.items()
            if o != rid and o in self.tracks
        }
        own = info.map
        # every map here is in the shared frame: where any robot went, before the audit
        # began as well, a wall is no conflict (copies here, paths in the audit's thread)
        everyone = [
            self.tracks[o].since(other.corrected_s)
            for o, other in main.robots.items()
            if o in self.tracks
        ]
        seen = mine is not None and len(mine) > 0 and bool(theirs)
        where = contradicted_where(theirs, {rid: mine}, (main.merged, own)) if seen else None

        def audit() -> tuple[list[tuple], float, float]:
            moments = where(np.zeros(3)) if where is not None else []
            paths = [p for t in everyone for p in t.paths()]
            fits = fit_at([m for _, m in earlier], own, np.zeros(3), paths, paths)
            roots = [ev for (root, _), ev in zip(earlier, fits, strict=True) if root]
            if sum(ev["overlap_m2"] for ev in roots) < MIN_OVERLAP_M2:
                roots = fits
            conflicts = sum(ev["conflict_share"] * ev["walls_inside"] for ev in roots)
            inside = sum(ev["walls_inside"] for ev in roots)
            return moments, conflicts / max(inside, 1.0), sum(ev["overlap_m2"] for ev in roots)

        return audit


def log_evidence(rows, level: int, logger: logging.Logger = log) -> None:
    """The first ``UNDO_EVIDENCE_LOGGED`` moments that contradict a frame (``Audit.evidence``'s
    rows): who looked from where, and where the frame put the other."""
    for o, m, t, viewer, vx, vy, px, py in list(rows)[:UNDO_EVIDENCE_LOGGED]:
        who, whom = (o, m) if viewer == 0 else (m, o)
        logger.log(
            level,
            "  at %.1f s %s at (%.2f, %.2f) saw clear where the frame put %s: "
            "(%.2f, %.2f), %.1f m away",
            t,
            who,
            vx,
            vy,
            whom,
            px,
            py,
            math.hypot(px - vx, py - vy),
        )
