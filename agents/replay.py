"""Replaying robots' map updates on worker processes, off the coordinator's thread.

A robot sends most of its map changes as the merge that made them (``MergeOp``) or the
keyframe moves of a loop closure (``CorrectionOp``); the receiver recomputes the cells,
bit for bit. That recomputation was 33-54 % of the coordinator thread's work with 3
robots and 70 % with 25 (``polyswarm bench cycle``), and only GEOS releases the GIL, so
threads cannot share it out: processes can.

Each worker process holds the copies of some robots' maps (and their ``Atlas``) and
applies their updates in the order they were sent; it returns the cells each update
changed. The coordinator keeps a mirror of every copy, updated from those cells (a
dictionary update), so the merged map, planning and sightings read the mirror as before.
Taking the cells in, and waiting for them when a merge is due, was 11 % of the thread's
work on the maze with 3 robots, where replaying had been 33 % (``polyswarm bench cycle``,
stage shares ``collect`` and ``replay``). When the coordinator keeps state,
the workers also journal the copies they hold (each delta flushed to disk): that was
16 % of the coordinator thread's work in a 10-robot load run.

Messages to a worker, in order per robot (pickled by the sender):

* ``("update", rid, epoch, kind, op, stamp_s, sent_s)``: a decoded merge, correction or
  delta, the robot's stamp and the sender's clock (the pool's lag is measured);
* ``("set", rid, epoch, map, atlas)``: the robot's whole map (a resync, a restore, a
  handover from a robot that explored alone); ``atlas`` None keeps the one held;
* ``None``: stop.

Results: ``Replayed`` tuples. ``epoch`` is the coordinator's count of whole maps set
for a robot: results of updates sent before the last ``set`` are stale and dropped.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import pickle
import queue
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from agents import persist
from polyswarm.errors import MapError, PolyswarmError
from polyswarm.polymap import GridPolyMap, MapDelta
from polyswarm.slam.follow import Atlas, largest_move_m, replay_correction
from protocols.mapcodec import encode_delta

log = logging.getLogger(__name__)

# a worker that does not stop within this after being asked is terminated (s)
STOP_TIMEOUT_S = 5.0
# an idle worker checks this often whether the coordinator still lives (s): one killed
# with SIGKILL cannot stop its workers, they stop themselves
PARENT_CHECK_S = 1.0


@dataclass(frozen=True)
class Replayed:
    """What one update did to a robot's map copy on its worker."""

    rid: str
    epoch: int
    kind: str  # "merge", "correct" or "delta"
    stamp_s: float
    delta: MapDelta | None  # the cells it changed (None: nothing, an old update)
    error: str | None = None  # it did not apply (a gap): fetch the robot's map
    cpu_ms: float = 0.0  # the worker's processor time for it
    moved_m: float = 0.0  # a correction's largest keyframe move
    sent_s: float = 0.0  # when it was sent (``time.perf_counter`` of the sender)


def apply_update(
    pmap: GridPolyMap | None, atlas: Atlas, kind: str, op
) -> tuple[GridPolyMap, Atlas, MapDelta | None]:
    """One robot update applied to its map copy: the new map, atlas and the cells it
    changed (None when it changed nothing). A merge adds its keyframe to ``atlas``; a
    correction returns a new one. Raises MapError (a gap) when it does not apply, and
    then changes nothing."""
    if pmap is None:
        if op.base_version > 0:
            raise MapError(f"the first update of a map starts at version {op.base_version}")
        pmap = GridPolyMap(op.cell_size)
    if kind == "merge":
        res = pmap.replay(op)
        if op.keyframe is not None:
            atlas.add(op.keyframe, op.polygon, op.options)
        if not res.changed:
            return pmap, atlas, None
        cells = tuple(res.map.cells[i] for i in sorted(res.changed))
        return res.map, atlas, MapDelta(op.cell_size, op.base_version, op.version, cells)
    if kind == "correct":
        out, atlas, changed = replay_correction(pmap, atlas, op)
        return out, atlas, MapDelta(op.cell_size, op.base_version, op.version, tuple(changed))
    out = pmap.apply_delta(op)
    return out, atlas, (op if out is not pmap else None)


def _worker(inbox, results: Connection, state_dir: str | None) -> None:
    """A worker's loop: robots' map copies, updated in order (and journaled to
    ``state_dir``, as the coordinator's state, when it keeps one)."""
    maps: dict[str, GridPolyMap | None] = {}
    atlases: dict[str, Atlas] = {}
    journal = persist.CoordinatorJournal(state_dir) if state_dir else None
    while (raw := receive(inbox)) is not None:
        msg = pickle.loads(raw)
        if msg[0] == "drop":  # the robot left the merged map: its copy is journaled aside
            maps.pop(msg[1], None)
            atlases.pop(msg[1], None)
            persist.record(journal, "robot_withdrawn", msg[1])
            continue
        if msg[0] == "set":
            _, rid, epoch, pmap, atlas = msg
            maps[rid] = pmap
            if atlas is not None or rid not in atlases:
                atlases[rid] = atlas if atlas is not None else Atlas()
            if pmap is not None:
                persist.record(journal, "robot_map", rid, pmap)
            continue
        _, rid, epoch, kind, op, stamp_s, sent_s = msg
        c0 = time.thread_time()
        atlas = atlases.setdefault(rid, Atlas())
        try:
            pmap, atlas, delta = apply_update(maps.get(rid), atlas, kind, op)
        except PolyswarmError as e:
            why = str(e) or type(e).__name__
            results.send(Replayed(rid, epoch, kind, stamp_s, None, why, sent_s=sent_s))
            continue
        except Exception as e:  # a bug must not stop the other robots' replays
            why = f"replay failed: {e!r}"
            results.send(Replayed(rid, epoch, kind, stamp_s, None, why, sent_s=sent_s))
            continue
        maps[rid], atlases[rid] = pmap, atlas
        moved = largest_move_m(op) if kind == "correct" else 0.0
        cpu_ms = (time.thread_time() - c0) * 1e3
        if delta is not None:  # as the cells it changed: a restore needs no merge
            persist.record(journal, "robot_delta", rid, encode_delta(delta), pmap)
        results.send(Replayed(rid, epoch, kind, stamp_s, delta, None, cpu_ms, moved, sent_s))


def receive(inbox) -> bytes | None:
    """A worker's next message (None: stop). While idle it checks every
    ``PARENT_CHECK_S`` whether the coordinator still lives: one killed with SIGKILL
    cannot stop its workers, they stop themselves."""
    parent = mp.parent_process()
    while True:
        try:
            return inbox.get(timeout=PARENT_CHECK_S)
        except queue.Empty:
            if parent is not None and not parent.is_alive():
                return None  # no orphans left behind


@dataclass
class Worker:
    proc: mp.Process
    inbox: object  # multiprocessing Queue: messages in (a feeder thread sends, never blocks)
    results: Connection  # its own pipe out: a killed worker cannot hold a lock others need


def start_process(ctx, target, state_dir: str | None) -> Worker:
    """A worker process running ``target(inbox, results, state_dir)``."""
    inbox = ctx.Queue()
    results, out = ctx.Pipe(duplex=False)
    p = ctx.Process(target=target, args=(inbox, out, state_dir), daemon=True)
    p.start()
    out.close()  # the worker's end
    return Worker(p, inbox, results)


def stop_process(w: Worker, timeout_s: float | None) -> None:
    """Stop a worker: asked to (``timeout_s`` None: within ``STOP_TIMEOUT_S``), or
    after ``timeout_s``, terminated."""
    if timeout_s is None:
        with contextlib.suppress(OSError, ValueError):
            w.inbox.put(None)
        timeout_s = STOP_TIMEOUT_S
    w.proc.join(timeout_s)
    if w.proc.is_alive():
        w.proc.terminate()
        w.proc.join(1.0)
    w.results.close()
    w.inbox.close()
    w.inbox.cancel_join_thread()


class ReplayPool:
    """``workers`` processes replaying robots' updates; robots are dealt to them in the
    order they first appear. ``poll()`` returns what finished. With ``state_dir`` the
    workers journal the robots' map copies there (``persist.CoordinatorJournal``: a
    snapshot and the deltas since, each flushed to disk), off the coordinator's thread."""

    def __init__(self, workers: int, state_dir: str | None = None) -> None:
        if workers < 1:
            raise ValueError(f"a replay pool needs at least one worker, got {workers}")
        self._state_dir = None if state_dir is None else str(state_dir)
        self._ctx = mp.get_context("spawn")  # no fork of a process with Zenoh threads
        self._workers = [self._start_worker() for _ in range(workers)]
        self._home: dict[str, int] = {}  # robot -> its worker
        self.restarts = 0

    @property
    def workers(self) -> int:
        return len(self._workers)

    @property
    def pids(self) -> list[int]:
        """The workers' process ids (a supervisor's or a test's view)."""
        return [w.proc.pid for w in self._workers]

    def _start_worker(self) -> Worker:
        return start_process(self._ctx, _worker, self._state_dir)

    def _worker_of(self, rid: str) -> int:
        if rid not in self._home:
            self._home[rid] = len(self._home) % len(self._workers)
        return self._home[rid]

    def update(self, rid: str, epoch: int, kind: str, op, stamp_s: float) -> None:
        self._send(rid, ("update", rid, epoch, kind, op, stamp_s, time.perf_counter()))

    def set_map(self, rid: str, epoch: int, pmap: GridPolyMap | None, atlas: Atlas | None):
        self._send(rid, ("set", rid, epoch, pmap, atlas))

    def drop(self, rid: str) -> None:
        """Forget a robot's copy (after the updates sent before), its journal set aside."""
        self._send(rid, ("drop", rid))

    def _send(self, rid: str, msg: tuple) -> None:
        # pickled here, not on the queue's feeder thread, where a failure would only print
        self._workers[self._worker_of(rid)].inbox.put(pickle.dumps(msg, pickle.HIGHEST_PROTOCOL))

    def poll(self, wait_s: float = 0.0) -> tuple[list[Replayed], list[str]]:
        """Finished updates (waiting up to ``wait_s`` for any), and the robots whose
        worker died (their copies are lost: set them again)."""
        done: list[Replayed] = []
        dead: set[int] = set()
        readers = {w.results: k for k, w in enumerate(self._workers)}
        for conn in wait(list(readers), timeout=wait_s):
            k = readers[conn]
            try:
                while conn.poll():
                    done.append(conn.recv())
            except (EOFError, OSError):  # it exited (perhaps in the middle of a result)
                dead.add(k)
        dead |= {k for k, w in enumerate(self._workers) if not w.proc.is_alive()}
        lost = []
        for k in sorted(dead):
            old = self._workers[k]
            log.error("replay worker %d exited (code %s): restarting it", k, old.proc.exitcode)
            stop_process(old, 0.0)
            self.restarts += 1
            self._workers[k] = self._start_worker()
            lost += [rid for rid, home in self._home.items() if home == k]
        return done, lost

    def close(self) -> None:
        for w in self._workers:
            with contextlib.suppress(OSError, ValueError):
                w.inbox.put(None)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for w in self._workers:
            stop_process(w, max(0.0, deadline - time.monotonic()))

    def __enter__(self) -> ReplayPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
