"""The swarm's joint pose graph on a thread of the coordinator (``polyswarm.frames.jointgraph``).

Every ``JOINT_PERIOD_S`` simulated seconds the keyframes of the robots in the merged map
(their ledgers: the merges and corrections the coordinator replayed) are matched with
each other where they have not been yet, and the graph over all of them is solved. A
robot one of whose keyframes that another robot's walls hold would move by
``PRIOR_MOVE_M`` or more is sent ``priors``: where the joint solution puts every such
keyframe of it. It holds them in its own pose graph; its map follows, and the
coordinator replays that correction like any other.

The reference robot (its map is not moved) is the first robot, in name order, whose
frame nobody audits (its start was given, or its frame is the map's). Priors are the
solution for the ledgers as they were when the solve began: a robot that corrected
itself since gets none from that solve (they would undo its correction), but the next's."""

from __future__ import annotations

import logging
import time
from concurrent.futures import Future, ThreadPoolExecutor

from polyswarm.frames.jointgraph import (
    PRIOR_MOVE_M,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RAD,
    JointGraph,
    moved_m,
)
from polyswarm.slam.follow import quantize_pose
from protocols.frame_messages import MAX_PRIORS, Priors

log = logging.getLogger(__name__)

JOINT_PERIOD_S = 10.0  # simulated seconds between solves (as the frames' audits)


class JointCorrections:
    """The joint pose graph's edges and its solves, for one coordinator."""

    def __init__(self) -> None:
        self.graph = JointGraph()
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="jointgraph")
        self._running: Future | None = None
        self._last_s = -float("inf")
        self.solves = 0
        self.priors_sent = 0
        # what the last solve saw: the edges, and the corrections of each robot's map
        self._solved: tuple | None = None
        self._moved_at_start: dict[str, int] = {}  # each robot's corrections when it began

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def tick(self, main, now_s: float, audited: set[str]) -> list[tuple[str, Priors]]:
        """Take a finished solve (the priors to send); start one when due. ``audited``:
        robots whose frames this coordinator found (not a reference)."""
        out = []
        if self._running is not None and self._running.done():
            try:
                out = self._fresh(main, self._running.result())
                self.priors_sent += len(out)
            except Exception:  # a failed solve must not stop the coordinator: retried
                log.exception("the joint pose graph failed")
            self._running = None
        if self._running is None and now_s - self._last_s >= JOINT_PERIOD_S:
            ledgers = {
                rid: info.ledger.snapshot()
                for rid, info in main.robots.items()
                if info.ledger and info.map is not None
            }
            reference = next((r for r in sorted(ledgers) if r not in audited), None)
            if len(ledgers) >= 2 and reference is not None:
                self._last_s = now_s
                frames = {rid: main.robots[rid].frame for rid in ledgers}
                moved = {rid: main.robots[rid].ledger.corrections for rid in ledgers}
                self._moved_at_start = moved
                self._running = self._pool.submit(self._solve, ledgers, reference, frames, moved)
        return out

    def _fresh(self, main, solved: list[tuple[str, Priors]]) -> list[tuple[str, Priors]]:
        """The priors of a finished solve, less those for a robot whose map was corrected
        (a loop of its own) while it ran: they would pull its keyframes back to where
        they were before; the next solve, due in ``JOINT_PERIOD_S``, sees the correction."""
        out = []
        for rid, priors in solved:
            info = main.robots.get(rid)
            if info is None or info.ledger is None:
                continue
            if info.ledger.corrections != self._moved_at_start.get(rid):
                log.info("joint pose graph: priors to %s dropped: its map moved meanwhile", rid)
                continue
            out.append((rid, priors))
        return out

    def _solve(self, ledgers, reference: str, frames, moved) -> list[tuple[str, Priors]]:
        t0 = time.perf_counter()
        found = self.graph.find_edges(ledgers)
        seen = (len(self.graph.edges), reference, tuple(sorted(moved.items())))
        if seen == self._solved:  # no new edge, no map corrected: the same solution
            return []
        self._solved = seen
        solved = self.graph.solve(ledgers, reference)
        self.solves += 1
        out = []
        for rid, poses in sorted(solved.items()):
            move = moved_m(ledgers[rid], poses)
            if move < PRIOR_MOVE_M:
                continue
            # the newest keyframes, if ever more than a message holds (12 bytes each)
            q = tuple((kid, *quantize_pose(poses[kid])) for kid in sorted(poses)[-MAX_PRIORS:])
            out.append((rid, Priors(frames[rid], PRIOR_SIGMA_M, PRIOR_SIGMA_RAD, q)))
            log.info(
                "joint pose graph: %d priors to %s (moves a keyframe %.3f m)", len(q), rid, move
            )
        log.info(
            "joint pose graph: %d robots, %d inter-robot edges (%d new), solved in %.0f ms",
            len(ledgers),
            len(self.graph.edges),
            found,
            (time.perf_counter() - t0) * 1e3,
        )
        return out
