"""Robots whose start poses nobody gave: exploring alone until their frame is found.

A robot without a start pose in ``[[robots]]`` maps in a frame of its own (its start).
Until the coordinator knows where that frame lies in the shared map frame:

* it explores its own map: a coordinator of its own (``solo``) takes its map updates,
  poses and status, and assigns it frontiers of its map, in its frame. Nothing of it
  enters the merged map, and the other robots are not planned around it;
* every ``MATCH_PERIOD_S`` its map is matched with the merged map
  (``polyswarm.frames.mapmatch.match_maps``, in a worker thread: a match took 0.1-2.9 s on
  recorded maps of the procedural worlds, 2.0-2.9 s on the thesis's 80 m loop;
  the pose's symmetric images are not checked, the sightings that commit a frame rule
  them out), and every match, accepted or not, is logged with its evidence;
* a match's candidate poses that the robots' sightings contradict are left out
  (``polyswarm.frames.sighting``: the frame would put one robot where another's lidar looked
  and saw nothing); in a symmetric building that is what tells the truth from its
  rotated images;
* while a match proposes a frame, the robot is drawn towards where that frame puts the
  nearest robot of the swarm (``Coordinator.rendezvous`` of its solo coordinator): seen
  there, in a few places, the robots confirm the frame; a wrong frame puts the other
  robot where the robot finds nobody, and the sightings contradict it. The other robot
  is not drawn: sent towards the waiting one as well, it sought goals behind doors it
  could not plan through (office launches seeds 0-1: 22 and 8 failed plans, one run
  350 s of wall time for 142 s; without, seeds 0-4: 0-11 failed plans, at most 153 s).
  Once the robots were seen where the candidate puts them (``TOUR_FIRST_SEEN``), the
  robot tours standpoints in sight of the other before its own frontiers (a right frame
  in the maze stayed seen in two places for 30 matches, 150 s, while the robot explored
  what the swarm had mapped);
* once successive matches agree and the robots saw each other where they put them
  (``FrameEstimate``), the robot is sent an ``anchor``:
  the pose of its frame in the shared frame. It moves its pose graph, keyframes and pose
  by it; its map follows as a correction of every keyframe, which its solo coordinator
  replays like any other;
* its first pose that names the anchor hands it over: the main coordinator takes its
  map copy (now in the shared frame), merges it, and coordinates it with the others;
* from then on its frame is audited every ``AUDIT_PERIOD_S`` on what came since the
  hand-over: the sightings, and its map against the maps of the robots whose frames
  are not in doubt (or, where it does not overlap them, of those merged before it;
  ``polyswarm.frames.mapmatch.fit_at``). ``UNDO_CONTRADICTIONS`` moments where one robot
  looked where another's pose put it and saw nothing, or ``UNDO_AUDITS`` audits in a
  row where ``UNDO_CONFLICT_SHARE`` of the walls the maps share stand in the other's
  clear space, undo the merge: its map leaves the merged map
  (``Coordinator.withdraw``; nothing is lost, the robot keeps it), it is sent an
  ``own`` anchor (the shared frame withdrawn: its coordinates are a frame of its own
  again) and waits, explores and is matched as before. Its sightings are kept: they
  rule the withdrawn frame out of the next matches.

Robots that wait form teams. Every ``MATCH_PERIOD_S`` a waiting team's map is also
matched with the map of a waiting team whose lead's id sorts first, by the same rules
(successive agreeing matches, the robots seen where the frame puts them, drawn to meet
while a candidate stands). Once committed, the team's robots are sent a ``team`` anchor:
they move into the other team's frame and its coordinator plans for them all (two waiting
robots 11 m apart in the same corridor of the loop both drove down it for 120 s, loop
seed 0). A team is matched with the merged map as one map, and placed as one: each of its
robots is anchored to the same frame and handed over on its own.

``POLYSWARM_WRONG_ANCHOR=r2:dx,dy,deg`` (``polyswarm launch --wrong-anchor``) commits
robot r2's first frame that far off (metres, metres, degrees, in the frame's own axes):
a fault injection that shows a wrong merge undone.
"""

from __future__ import annotations

import logging
import math
import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from agents.audits import Audit, Audits, log_evidence
from agents.framematch import Matched, contradicted_where, match_frame
from polyswarm.config import Config
from polyswarm.errors import PolyswarmError
from polyswarm.frames.estimate import FrameEstimate
from polyswarm.frames.sighting import (
    MIN_CONTRADICTIONS,
    Sighting,
    Track,
    distinct_places,
    mutual_seen,
)
from polyswarm.se2 import compose, inverse, transform_points
from protocols.messages import Anchor, Pose

log = logging.getLogger(__name__)

MATCH_PERIOD_S = 5.0  # simulated (or sensor) seconds between matches of one robot's map
MIN_MAP_M2 = 10.0  # a map smaller than this (either one) is not matched yet
RESEND_S = 5.0  # an anchor the robot's poses do not name yet is sent again after this
SOLO_ID_OFFSET = 97_000_000  # solo coordinators' target ids start this far apart
WRONG_ANCHOR_ENV = "POLYSWARM_WRONG_ANCHOR"
# places the robots were seen at a candidate frame before the waiting robot tours
# standpoints ahead of its own frontiers: matches at wrong poses were seen anywhere 13
# times of 892, at right ones 552 of 1,003 (50 launches, launch-sightings-arc.json); a
# tour at a wrong frame finds nobody and the sightings then forget it
TOUR_FIRST_SEEN = 1


def robot_offset(text: str, what: str = "wrong anchor") -> tuple[str, np.ndarray] | None:
    """``r2:dx,dy,deg`` -> ("r2", offset (m, m, rad)); "" -> None."""
    if not text:
        return None
    try:
        rid, rest = text.split(":", 1)
        dx, dy, deg = (float(v) for v in rest.split(","))
    except ValueError:
        raise PolyswarmError(f"{what} {text!r}: expected ROBOT:dx,dy,deg") from None
    if not all(math.isfinite(v) for v in (dx, dy, deg)):
        raise PolyswarmError(f"{what} {text!r}: not finite")
    return rid, np.array([dx, dy, math.radians(deg)])


def wrong_anchor_fault(text: str) -> tuple[str, np.ndarray] | None:
    """``r2:dx,dy,deg`` -> ("r2", offset (m, m, rad)); "" -> None."""
    return robot_offset(text, "wrong anchor")


@dataclass
class _Pairing:
    """A waiting team's frame in another waiting team's, and how far finding it has got."""

    frames: FrameEstimate = field(default_factory=FrameEstimate)
    last_match_s: float = -math.inf
    matching: Future | None = None
    matches: int = 0
    seen_at_candidate: int = 0  # places the robots were seen at the candidate frame


@dataclass
class _Waiting(_Pairing):
    """A robot exploring without the swarm (alone, or in a team of waiting robots), and
    how far finding its frame in the shared one has got (its ``_Pairing`` fields)."""

    # agents.coordinator.Coordinator of its team: of this robot alone, or, once it joined
    # a team, the team's (shared by the team's robots)
    solo: object = None
    # a team's member: the robot whose frame it speaks in (None: its own; it leads its team)
    lead: str | None = None
    teams: dict[str, _Pairing] = field(default_factory=dict)  # lead -> its frame in theirs
    join: str | None = None  # the team its ``team`` anchor (sent, not yet named) joins
    anchor: Anchor | None = None  # sent, not yet named by the robot's poses
    anchor_sent_s: float = -math.inf
    # the anchor its poses name while it waits: 0 (its start's frame), or the ``own``
    # anchor that withdrew its frame; ``release``: that anchor, until its poses name it
    frame: int = 0
    release: Anchor | None = None
    epoch: int = 0  # its map copy's replay epoch in the main coordinator, before it left


class Anchoring(Audits):
    """The robots of the swarm whose frames are not known yet, and the audits of those
    whose frames were found here (see the module)."""

    def __init__(self, cfg: Config, unknown: list[str]) -> None:
        self.cfg = cfg
        self.waiting = {}
        self._solos = 0  # solo coordinators made (their target ids must differ)
        for rid in unknown:
            self.waiting[rid] = _Waiting(solo=self._solo(rid, np.zeros(3)))
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="mapmatch") if unknown else None
        # audits on a thread of their own: queued behind matches of a large map (94 s of
        # wall time each on the maze, beside the robots' processes on 2 cores), an undo
        # came 169 simulated seconds after the wrong merge
        self._audit_pool = ThreadPoolExecutor(1, thread_name_prefix="audit") if unknown else None
        self.anchored: dict[str, np.ndarray] = {}  # robot -> its frame in the shared one
        self.audits: dict[str, Audit] = {}  # robots merged on a frame found here
        self.undone = 0  # merges undone
        self._fault = wrong_anchor_fault(os.environ.get(WRONG_ANCHOR_ENV, ""))
        # every robot's poses and clear profiles: in the shared frame, or, while it
        # waits, in its own
        self.tracks: dict[str, Track] = {}

    def _solo(self, rid: str, start: np.ndarray):
        """A coordinator for ``rid`` alone, its start at ``start`` in its own frame."""
        from agents.coordinator import Coordinator

        solo = Coordinator(self.cfg, {rid: tuple(float(v) for v in start)})
        solo.own_maps = True  # its robots are not in the shared frame: no merged map
        # target ids of its own: the main coordinator's must not repeat one it reached
        self._solos += 1
        solo._next_id = (solo._next_id + SOLO_ID_OFFSET * self._solos) % 1_000_000_000
        return solo

    def owner(self, rid: str, main):
        """The coordinator that takes this robot's messages now."""
        w = self.waiting.get(rid)
        return main if w is None else w.solo

    def coordinators(self) -> list:
        """The waiting teams' coordinators (a team's robots share one)."""
        return list({id(w.solo): w.solo for w in self.waiting.values()}.values())

    def members(self, lead: str) -> list[str]:
        """The robots of ``lead``'s team: it first, then those that joined it."""
        return [lead, *sorted(r for r, w in self.waiting.items() if w.lead == lead)]

    def _team_map(self, lead: str):
        """The map of ``lead``'s team, in its frame: its own, or its team's merged map."""
        solo = self.waiting[lead].solo
        return solo.robots[lead].map if len(solo.robots) == 1 else solo.merged

    def close(self) -> None:
        for pool in (self._pool, self._audit_pool):
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)

    # -- each loop of the coordinator ---------------------------------------------------------

    def tick(self, main, now_s: float) -> list[tuple[str, Anchor]]:
        """Start the matches and audits that are due, take the finished ones; the anchors
        to send."""
        out = self._audit(main, now_s)
        main.rendezvous = {}  # the swarm's robots drawn to waiting ones (``_rendezvous``)
        for solo in self.coordinators():
            solo.rendezvous, solo.tour_first = {}, set()
        for rid, w in list(self.waiting.items()):
            self._take(rid, w)
            if w.release is not None and now_s - w.anchor_sent_s >= RESEND_S:
                w.anchor_sent_s = now_s  # the withdrawal, until its poses name it
                out.append((rid, w.release))
            if w.anchor is not None:
                if now_s - w.anchor_sent_s >= RESEND_S:
                    w.anchor_sent_s = now_s
                    out.append((rid, w.anchor))
                continue
            if w.lead is not None or self._busy(rid):
                continue  # a team's member (its lead is matched), or a team on the move
            joining = self._joined_by(rid)  # robots on their way in: placed once they are
            if w.frames.pose is not None and not joining:  # committed
                out += self._place(rid, w.frames.pose, now_s)
                continue
            peer = next((p for p, t in w.teams.items() if t.frames.pose is not None), None)
            if peer is not None and not joining and self._leads(peer) and not self._busy(peer):
                out += self._place(rid, w.teams[peer].frames.pose, now_s, peer)
                continue
            own = self._team_map(rid)
            big = own is not None and own.explored_area() >= MIN_MAP_M2
            if (
                big
                and w.matching is None
                and now_s - w.last_match_s >= MATCH_PERIOD_S
                and main.merged.explored_area() >= MIN_MAP_M2
            ):
                w.last_match_s = now_s
                theirs = {o: (self.tracks.get(o), info) for o, info in main.robots.items()}
                where, seen_at, tracks = self._evidence(rid, theirs, main.merged)
                w.matching = self._pool.submit(
                    match_frame, main.merged, own, where, seen_at, w.frames.candidate, tracks
                )
            if big:
                self._match_teams(rid, w, now_s)
            self._rendezvous(rid, w, main)
        return out

    def _leads(self, rid: str) -> bool:
        w = self.waiting.get(rid)
        return w is not None and w.lead is None

    def _busy(self, lead: str) -> bool:
        """Some robot of ``lead``'s team has an anchor on its way."""
        return any(self.waiting[m].anchor is not None for m in self.members(lead))

    def _joined_by(self, lead: str) -> bool:
        """Robots are on their way into ``lead``'s team (their ``team`` anchors sent): the
        team is placed once they are in."""
        return any(w.join == lead for w in self.waiting.values())

    def _place(self, lead: str, pose, now_s: float, team: str | None = None) -> list:
        """Anchor every robot of ``lead``'s team at ``pose``: the frame of its team in the
        shared one, or (``team``) in that team's frame."""
        x, y, th = (float(v) for v in (self._committed(lead, pose) if team is None else pose))
        robots = self.members(lead)
        log.info(
            "robot%s %s anchored at (%.2f m, %.2f m, %.1f deg)%s",
            "s" if len(robots) > 1 else "",
            ", ".join(robots),
            x,
            y,
            math.degrees(th),
            f" in the frame of {team}'s team" if team else "",
        )
        out = []
        for rid in robots:
            w = self.waiting[rid]
            w.anchor = Anchor(w.frame + 1, x, y, th, team=team is not None)
            w.anchor_sent_s, w.join = now_s, team
            out.append((rid, w.anchor))
        return out

    def _match_teams(self, rid: str, w: _Waiting, now_s: float) -> None:
        """Start a match of ``rid``'s team's map with the map of a waiting team whose lead
        sorts before it (the one matched least lately), when due. Not while either has a
        candidate frame in the shared one: it is on its way to the swarm (and the matching
        thread is shared)."""
        if w.frames.candidate is not None or any(p.matching for p in w.teams.values()):
            return
        due = []
        for lead in self.waiting:
            if lead >= rid or not self._leads(lead) or self._busy(lead):
                continue
            if self.waiting[lead].frames.candidate is not None:
                continue
            p = w.teams.setdefault(lead, _Pairing())
            theirs = self._team_map(lead)
            if (
                now_s - p.last_match_s >= MATCH_PERIOD_S
                and theirs is not None
                and theirs.explored_area() >= MIN_MAP_M2
            ):
                due.append((p.last_match_s, lead, theirs))
        if not due:
            return
        _, lead, theirs = min(due, key=lambda d: d[:2])
        p = w.teams[lead]
        p.last_match_s = now_s
        solo = self.waiting[lead].solo
        team = {o: (self.tracks.get(o), solo.robots[o]) for o in self.members(lead)}
        where, seen_at, tracks = self._evidence(rid, team, theirs)
        own = self._team_map(rid)
        p.matching = self._pool.submit(
            match_frame, theirs, own, where, seen_at, p.frames.candidate, tracks
        )

    def _take(self, rid: str, w: _Waiting) -> None:
        """Take ``rid``'s finished matches: with the merged map, and with other teams'."""
        if w.matching is not None and w.matching.done():
            self._took(rid, w, w.matching, "the merged map")
            w.matching = None
        for lead, p in w.teams.items():
            if p.matching is not None and p.matching.done():
                self._took(rid, p, p.matching, f"the map of {lead}'s team")
                p.matching = None

    def _committed(self, rid: str, pose: np.ndarray) -> np.ndarray:
        """The frame sent for a committed ``pose``: the pose, or, for the robot of a
        wrong-anchor fault injection, the first time, that far off."""
        if self._fault is None or self._fault[0] != rid:
            return pose
        off, self._fault = self._fault[1], None
        log.warning("fault injection: %s anchored %s off its committed frame", rid, off)
        return compose(pose, off)

    def _undo(self, rid: str, main, now_s: float) -> Anchor:
        """Take ``rid`` out of the merged map and back to waiting; the ``own`` anchor
        that withdraws its frame."""
        a = self.audits.pop(rid)
        log.warning(
            "robot %s: %d moments since its merge contradict its frame, its map conflicted "
            "with earlier ones in %d audits in a row: merge undone",
            rid,
            len(a.evidence),
            a.conflicting,
        )
        log_evidence(a.evidence, logging.WARNING, log)
        info = main.withdraw(rid)
        solo = self._solo(rid, info.start)  # its start, in the coordinates it speaks in
        mine = solo.robots[rid]
        mine.alive, mine.pose, mine.pose_t = info.alive, info.pose, info.pose_t
        if info.map is not None:  # (an atlas only without a replay pool; else its next
            solo.on_robot_map(rid, info.map, info.atlas)  # correction fetches the map)
        release = Anchor(a.frame + 1, 0.0, 0.0, 0.0, own=True)
        self.waiting[rid] = _Waiting(
            solo=solo, frame=release.frame, release=release, anchor_sent_s=now_s, epoch=info.epoch
        )
        self.anchored.pop(rid, None)
        self.undone += 1
        return release

    def _rendezvous(self, rid: str, w: _Waiting, main) -> None:
        """Send a waiting robot towards where its candidate frame puts the nearest
        robot of the swarm (in its own frame): if the frame is right they see each other
        there and the frame is committed; if not, the robot finds the place empty (or a
        wall), the sightings contradict the frame and the next match leaves it out.
        Without a candidate in the shared frame, a candidate in another waiting team's
        frame draws it to that team's nearest robot.

        Once the swarm (or that team) has no frontier left, its robot nearest to where the
        frame puts the waiting one tours standpoints in sight of it too: a robot standing
        still is seen in one place however the other tours (rooms at unknown starts, seed
        3: two right frames seen in 1 and 2 places for 120 s, never merged)."""
        solo = w.solo
        me = solo.robots[rid].pose
        there, frame, seen = main, w.frames.candidate, w.seen_at_candidate
        for lead, p in w.teams.items():
            if frame is None and p.frames.candidate is not None and self._leads(lead):
                there, frame = self.waiting[lead].solo, p.frames.candidate
                seen = p.seen_at_candidate
        others = [r for r in there.robots.values() if r.alive and r.pose is not None]
        if frame is None or me is None or not others:
            return
        if seen >= TOUR_FIRST_SEEN:
            solo.tour_first.add(rid)
        at = transform_points(inverse(frame), np.array([r.pose[:2] for r in others]))
        k = int(np.argmin(np.hypot(*(at - me[:2]).T)))
        heading = compose(inverse(frame), others[k].pose)[2]  # its lidar looks this way
        solo.rendezvous[rid] = (float(at[k][0]), float(at[k][1]), float(heading))
        if there.out_of_frontiers and others[k].id not in there.rendezvous:
            x, y, th = (float(v) for v in compose(frame, me))  # the waiting one, their frame
            there.rendezvous[others[k].id] = (x, y, th)

    def _took(self, rid: str, w: _Pairing, done: Future, against: str) -> None:
        """A finished match of ``rid``'s team's map ``against`` a map (the merged map,
        ``w`` its ``_Waiting``, or another team's, ``w`` that ``_Pairing``)."""
        try:
            got: Matched = done.result()
        except Exception:  # a failed match must not stop the coordinator: logged, retried
            log.exception("matching the map of %s failed", rid)
            return
        if len(got.stale) >= MIN_CONTRADICTIONS and w.frames.candidate is not None:
            # a wrong candidate would draw the robot to an empty place until a match
            # proposed another (once 150 s: the maps then matched nowhere else)
            x, y, th = w.frames.candidate
            log.info(
                "candidate frame (%.2f m, %.2f m, %.1f deg) of %s contradicted by %d "
                "moments of the sightings: forgotten",
                x,
                y,
                math.degrees(th),
                rid,
                len(got.stale),
            )
            log_evidence(got.stale, logging.INFO, log)
            w.frames.forget_candidate()
            w.seen_at_candidate = 0
        m = got.match
        if m is None:
            log.info("map of %s not matched: %s", rid, got.why)
            return
        w.matches += 1
        before = w.frames.pose
        w.frames.add(m, got.seen)
        if m.proposed:  # the candidate is this match's pose now
            w.seen_at_candidate = got.seen
        log.info(
            "map of %s against %s (match %d): %s, seen %d time(s)%s",
            rid,
            against,
            w.matches,
            m.summary(),
            got.seen,
            "" if m.accepted else " (refused)",
        )
        if before is None and w.frames.pose is not None:
            log.info("frame of %s committed after %d matches with %s", rid, w.matches, against)

    def sighted(self, rid: str, stamp_s: float, pose: Pose) -> None:
        """A robot's pose, and its scan's clear profile if sent, for the tracks."""
        if not self.waiting and not self.audits:
            return  # every frame is known: no evidence is needed
        w = self.waiting.get(rid)
        if w is not None and not (w.frame - (w.frame > 0) <= pose.frame <= w.frame):
            return  # anchored, not yet handed over: between two frames
        track = self.tracks.setdefault(rid, Track())
        track.add(Sighting(stamp_s, (pose.x, pose.y, pose.theta), pose.clear))

    def _evidence(self, rid: str, theirs: dict, merged):
        """Two tests of a frame of ``rid``'s team in the frame of ``merged`` (the merged
        map, or another team's) on copies of the sightings so far, for the matching
        thread: the moments that contradict it (``_contradicted_where``), and how often
        the robots saw each other where it puts them (None, None without sightings); and
        the copies of the tracks (the other robots' in ``merged``'s frame, those of
        ``rid``'s team in its frame) whose paths the match spares walls along
        (``_match``). ``theirs``: robot -> (its track or None, its ``RobotInfo``), the
        robots of ``merged``. Every robot of the team looks for the others and is looked
        for (office seed 3: a team's lead was seen in 2 places of 3 for 60 s while its
        other robot's sightings went unused). A robot's poses from before its latest
        large correction are left out (they were sent from a frame that far off its map
        now)."""
        solo = self.waiting[rid].solo
        mine = {
            m: self.tracks[m].since(solo.robots[m].corrected_s)
            for m in self.members(rid)
            if m in self.tracks and m in solo.robots
        }
        theirs = {o: t.since(info.corrected_s) for o, (t, info) in theirs.items() if t}
        tracks = (list(theirs.values()), list(mine.values()))
        if not mine or not theirs:
            return None, None, tracks
        maps = (merged, self._team_map(rid))
        where = contradicted_where(theirs, mine, maps)

        def seen_at(frame: np.ndarray) -> int:
            """Places in ``merged``'s frame, all robots' sightings."""
            places = [
                mutual_seen(t, u, frame, maps) for t in theirs.values() for u in mine.values()
            ]
            return distinct_places(np.vstack(places))

        return where, seen_at, tracks

    def on_pose(self, rid: str, frame: int, map_version: int, main, own: bool = False) -> bool:
        """A pose of ``rid`` naming ``frame`` at its map ``map_version``: hands the robot
        over to ``main`` once it names its anchor and its solo coordinator's copy of its
        map has caught up (the anchor's correction replayed: the copy is in the shared
        frame). True when it was handed over now. ``own``: the pose says that anchor
        withdrew its frame (a coordinator restarted since learns it so)."""
        w = self.waiting.get(rid)
        if w is None:
            return False
        if own and frame > w.frame and w.anchor is None:
            w.frame = frame  # in a frame of its own, numbered so: not to be handed over
        if w.release is not None and frame >= w.release.frame:
            w.release = None  # its frame is its own now: the withdrawal is not sent again
        if frame <= w.frame or (w.anchor is not None and frame < w.anchor.frame):
            return False
        copy = w.solo.robots[rid].map
        if copy is None or copy.version < map_version:
            return False  # the correction is still on its way: the next pose tries again
        if w.anchor is not None and w.anchor.team:
            self._into_team(rid, w)
            return False

        del self.waiting[rid]
        # its copy and state; its team's other robots go on waiting with the coordinator
        solo = w.solo.robots[rid]
        if len(w.solo.robots) > 1:
            w.solo.withdraw(rid, "placed in the shared frame")
        if w.anchor is None:  # anchored by this coordinator before it restarted
            log.info("robot %s is in the shared frame already (anchor %d)", rid, frame)
            pose = np.zeros(3)  # its start in the shared frame is not known here
            self.tracks.pop(rid, None)  # poses in a frame not known here either
        else:
            pose = np.array([w.anchor.x, w.anchor.y, w.anchor.theta])
            self.audits[rid] = Audit(w.anchor.frame, since_s=main.now)
        self.anchored[rid] = pose
        if rid in self.tracks:  # its poses so far, in the shared frame
            self.tracks[rid] = self.tracks[rid].moved(pose)
        # in the shared frame now (the anchor's correction moved its map), its start too
        info = _take_over(main, rid, solo, compose(pose, solo.start))
        info.epoch = w.epoch + 1  # results of its earlier stay in the merged map are stale
        log.info("robot %s joins the swarm's map (%d matches)", rid, w.matches)
        return True

    def _into_team(self, rid: str, w: _Waiting) -> None:
        """``rid`` names its ``team`` anchor and its copy caught up (in the team's frame
        now): its team's coordinator takes it over, with its map and its track."""

        a, lead = w.anchor, w.join
        pose = np.array([a.x, a.y, a.theta])
        mine = w.solo.robots[rid]
        start = compose(pose, mine.start)  # its start, in the team's frame
        w.anchor, w.join, w.frame = None, None, a.frame
        w.frames, w.teams, w.matching = FrameEstimate(), {}, None  # of its old frame
        w.seen_at_candidate = 0
        if rid in self.tracks:
            self.tracks[rid] = self.tracks[rid].moved(pose)
        team = self.waiting.get(lead)
        if team is None or team.lead is not None:  # (held while robots join: not expected)
            log.warning("robot %s: the team of %s is gone; it waits alone", rid, lead)
            mine.start = start
            return
        if len(w.solo.robots) > 1:
            w.solo.withdraw(rid, f"joins the team of {lead}")
        _take_over(team.solo, rid, mine, start)
        w.solo, w.lead = team.solo, lead
        log.info("robot %s joins the team of %s: %s", rid, lead, ", ".join(self.members(lead)))


def _take_over(coord, rid: str, was, start: np.ndarray):
    """``coord`` takes ``rid`` over from another coordinator (``was``: its ``RobotInfo``
    there, its map copy already in ``coord``'s frame) with its start there; the new info."""
    from agents.coordinator import RobotInfo

    info = coord.robots[rid] = RobotInfo(rid, start)
    info.alive = was.alive
    if was.map is not None:
        coord.on_robot_map(rid, was.map, was.atlas)
    return info
