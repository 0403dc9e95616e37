"""Zenoh sessions and a small message bus for polyswarm processes.

* ``session_config``: explicit endpoints, multicast scouting off (nothing is found by
  accident), optionally a JSON5 file for LAN/TLS/ACL deployments;
* ``Bus``: typed publish/subscribe over one session. Callbacks run on Zenoh's threads,
  so received messages are decoded there and queued; the process handles them on its
  own thread with ``Bus.poll``. Maps and deltas go RELIABLE with BLOCK congestion
  control and are chunked (``protocols.chunks.CHUNK_BYTES``); telemetry may use DROP.
  Malformed messages are counted and logged (rate limited), never raised.

    with open_session(SessionSpec.client("tcp/127.0.0.1:7447")) as session:
        bus = Bus(session, sender="r1")
        bus.subscribe(keys.robot("r1").scan, Scan)
        bus.publish(keys.robot("r1").pose, Pose(1, 2, 0), stamp_s=t)
        for key, env, msg in bus.poll(timeout_s=0.1): ...
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import queue
import random
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import zenoh

from polyswarm.errors import CommsError, DecodeError
from protocols.chunks import MapChunk, MapKind, Reassembler, chunk_payload
from protocols.messages import Message, decode, encode

log = logging.getLogger(__name__)

QUEUE_LIMIT = 10_000  # messages waiting for the process thread; older telemetry is dropped
LEASE_MS = 3000  # liveliness lease: a silent process is declared gone after this
CONNECT_RETRY_S = 0.25  # a client retries its router this often while it is not up
LOG_EVERY_S = 5.0  # malformed-message warnings at most this often per key


class Mode:
    ROUTER = "router"
    PEER = "peer"
    CLIENT = "client"


@dataclass(frozen=True)
class SessionSpec:
    """How to open a session: mode, endpoints to listen on and connect to, or a file."""

    mode: str = Mode.CLIENT
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    config_file: str = ""  # a Zenoh JSON5 file; the fields above are applied on top

    @classmethod
    def router(cls, endpoint: str, config_file: str = "") -> SessionSpec:
        return cls(Mode.ROUTER, (endpoint,) if endpoint else (), (), config_file)

    @classmethod
    def client(cls, endpoint: str, config_file: str = "") -> SessionSpec:
        return cls(Mode.CLIENT, (), (endpoint,) if endpoint else (), config_file)


def session_config(spec: SessionSpec) -> zenoh.Config:
    if spec.config_file:
        path = Path(spec.config_file)
        if not path.is_file():
            raise CommsError(f"Zenoh config file not found: {path}")
        try:
            conf = zenoh.Config.from_file(str(path))
        except Exception as e:  # zenoh raises ZError with the parser's message
            raise CommsError(f"{path}: invalid Zenoh config: {e}") from e
    else:
        conf = zenoh.Config()
        conf.insert_json5("scouting/multicast/enabled", "false")
        # a peer that stops answering (killed, frozen, unplugged) is gone after the lease
        conf.insert_json5("transport/link/tx/lease", str(LEASE_MS))
        conf.insert_json5("transport/link/tx/keep_alive", "4")
    try:
        conf.insert_json5("mode", json.dumps(spec.mode))
        if spec.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(spec.listen)))
        if spec.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(spec.connect)))
    except Exception as e:
        raise CommsError(f"invalid Zenoh setting: {e}") from e
    return conf


@contextlib.contextmanager
def open_session(spec: SessionSpec, connect_timeout_s: float = 30.0) -> Iterator[zenoh.Session]:
    """A Zenoh session that is always closed (an unclosed one hangs at exit).

    A client retries for ``connect_timeout_s`` while its router is not up yet (processes
    of one launch, or a robot booting before the coordinator's machine)."""
    deadline = time.monotonic() + connect_timeout_s
    while True:
        try:
            session = zenoh.open(session_config(spec))
            break
        except CommsError:
            raise
        except Exception as e:
            if spec.mode == Mode.CLIENT and time.monotonic() < deadline:
                time.sleep(CONNECT_RETRY_S)
                continue
            where = ", ".join(spec.listen + spec.connect) or spec.config_file or "defaults"
            raise CommsError(f"cannot open a Zenoh {spec.mode} session ({where}): {e}") from e
    try:
        yield session
    finally:
        session.close()


# --- the bus -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Received:
    key: str
    sender: str
    seq: int
    stamp_s: float
    msg: Message
    payload: bytes | None = None  # a reassembled map or delta (for MapChunk streams)
    routed_at: float | None = None  # wall seconds the router stamped (the last chunk's)


@dataclass(frozen=True)
class LinkFaults:
    """Faults injected on reception, for tests of reliability: each received sample is
    dropped with ``drop``, delivered twice with ``dup``, or held back and delivered after
    the next one with ``reorder`` (probabilities; liveliness is not affected)."""

    drop: float = 0.0
    dup: float = 0.0
    reorder: float = 0.0
    seed: int = 0

    @classmethod
    def parse(cls, text: str) -> LinkFaults | None:
        """``drop=0.1,dup=0.05,reorder=0.05,seed=1`` (also the POLYSWARM_LINK_FAULTS
        environment variable); empty: None."""
        if not text.strip():
            return None
        vals: dict[str, float] = {}
        for item in text.split(","):
            key, _, v = item.partition("=")
            if key.strip() not in ("drop", "dup", "reorder", "seed"):
                raise CommsError(f"link faults: unknown key {key.strip()!r} in {text!r}")
            try:
                vals[key.strip()] = float(v)
            except ValueError:
                raise CommsError(f"link faults: {item!r} is not key=number") from None
        seed = int(vals.pop("seed", 0))
        if not all(0.0 <= p < 1.0 for p in vals.values()):
            raise CommsError(f"link faults: probabilities must be in [0, 1): {text!r}")
        return cls(seed=seed, **vals)


class Bus:
    """Typed publish/subscribe on one session, handled on the caller's thread."""

    def __init__(
        self,
        session: zenoh.Session,
        sender: str,
        faults: LinkFaults | None = None,
        inbox: queue.Queue | None = None,
    ) -> None:
        """``inbox``: another bus's receive queue, shared (one process on several links
        polls one of them for all)."""
        self.session = session
        self.sender = sender
        self._queue: queue.Queue[Received] = queue.Queue(QUEUE_LIMIT) if inbox is None else inbox
        self._injected = iter(range(1 << 62))  # sequence numbers of injected messages
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._seq: dict[str, int] = {}
        self._streams = 0
        self._handles: list = []
        self._reassembler = Reassembler()
        self._lock = threading.Lock()
        self._last_warning: dict[str, float] = {}
        self.bytes_sent: dict[str, int] = {}  # per key
        self.rejected = 0  # malformed messages received
        if faults is None:
            faults = LinkFaults.parse(os.environ.get("POLYSWARM_LINK_FAULTS", ""))
        self.faults = faults
        self._fault_rng = random.Random(faults.seed if faults else 0)
        self.injected = {"drop": 0, "dup": 0, "reorder": 0}

    # -- sending --------------------------------------------------------------------------

    def _publisher(self, key: str, reliable: bool) -> zenoh.Publisher:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self.session.declare_publisher(
                key,
                congestion_control=(
                    zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
                ),
                reliability=zenoh.Reliability.RELIABLE,
            )
            self._publishers[key] = pub
        return pub

    @property
    def inbox(self) -> queue.Queue:
        return self._queue

    def next_seq(self, key: str) -> int:
        s = self._seq.get(key, 0)
        self._seq[key] = s + 1
        return s

    def last_seq(self, key: str) -> int:
        """The sequence number of the last message sent on ``key`` (-1: none)."""
        return self._seq.get(key, 0) - 1

    def publish(self, key: str, msg: Message, stamp_s: float, reliable: bool = False) -> int:
        """Send one message; returns its size in bytes."""
        data = encode(msg, self.sender, self.next_seq(key), stamp_s)
        self._publisher(key, reliable).put(data)
        self.bytes_sent[key] = self.bytes_sent.get(key, 0) + len(data)
        return len(data)

    def map_chunks(self, kind: MapKind, payload: bytes, base: int, ver: int) -> list[MapChunk]:
        self._streams += 1
        return chunk_payload(kind, payload, base, ver, self._streams)

    def publish_map(
        self, key: str, kind: MapKind, payload: bytes, base: int, ver: int, stamp_s: float
    ) -> int:
        """Send an encoded map or delta, chunked, RELIABLE + BLOCK; returns bytes sent."""
        return sum(
            self.publish(key, c, stamp_s, reliable=True)
            for c in self.map_chunks(kind, payload, base, ver)
        )

    def serve_map(
        self, key: str, current: Callable[[], tuple[bytes, int]], kind: MapKind = MapKind.MAP
    ) -> None:
        """Answer queries on ``key`` with the full map ``current()`` = (payload, version):
        a ``polymap`` (``kind`` MAP) or all its cells (DELTA from version -1); no answer
        while ``current()`` is None."""

        def on_query(query: zenoh.Query) -> None:
            try:
                got = current()
                if got is None:
                    return
                payload, ver = got
                for c in self.map_chunks(kind, payload, -1, ver):
                    data = encode(c, self.sender, self.next_seq(key), time.time())
                    query.reply(query.key_expr, data)
                    self.bytes_sent[key] = self.bytes_sent.get(key, 0) + len(data)
            except Exception:  # a failing reply must not kill Zenoh's thread
                log.exception("answering a map query on %s failed", key)

        self._handles.append(self.session.declare_queryable(key, on_query))

    def fetch_map(self, key: str, timeout_s: float = 5.0) -> tuple[bytes, int] | None:
        """Query a map queryable; the reassembled payload and its version, or None."""
        try:
            replies = self.session.get(
                key, timeout=timeout_s, consolidation=zenoh.ConsolidationMode.NONE
            )
            asm = Reassembler(timeout_s=timeout_s)
            for reply in replies:
                if reply.ok is None:
                    continue
                try:
                    env, msg = decode(reply.ok.payload.to_bytes(), MapChunk)
                    done = asm.add(env.sender, msg, time.monotonic())
                except DecodeError as e:
                    self._warn(key, f"bad map reply: {e}")
                    continue
                if done is not None:
                    return done[1], done[0].ver
        except zenoh.ZError as e:
            self._warn(key, f"map query failed: {e}")
        return None

    # -- receiving ------------------------------------------------------------------------

    def _faulty(
        self, sample: zenoh.Sample, handle: Callable[[zenoh.Sample], None], hold: list
    ) -> None:
        """Deliver ``sample`` through the injected faults (see ``LinkFaults``); ``hold``
        is the subscription's own slot for a sample held back."""
        f = self.faults
        with self._lock:
            r = self._fault_rng.random()
            held = hold.pop() if hold else None
            if r < f.drop:
                self.injected["drop"] += 1
                out = []
            elif r < f.drop + f.dup:
                self.injected["dup"] += 1
                out = [sample, sample]
            elif r < f.drop + f.dup + f.reorder and held is None:
                self.injected["reorder"] += 1
                hold.append(sample)
                out = []
            else:
                out = [sample]
            if held is not None:
                out.append(held)  # the held-back sample arrives after a later one
        for s in out:
            handle(s)

    def subscribe(self, key: str, kind: type[Message]) -> None:
        """Queue every valid ``kind`` message on ``key`` (a key expression)."""

        hold: list = []  # a sample held back by fault injection (reordering)

        def on_sample(sample: zenoh.Sample) -> None:
            if self.faults is not None:
                self._faulty(sample, handle, hold)
            else:
                handle(sample)

        def handle(sample: zenoh.Sample) -> None:
            k = str(sample.key_expr)
            try:
                env, msg = decode(sample.payload.to_bytes(), kind)
                payload = None
                if isinstance(msg, MapChunk):
                    with self._lock:
                        done = self._reassembler.add(env.sender + k, msg, time.monotonic())
                    if done is None:
                        return
                    msg, payload = done
                ts = sample.timestamp  # a router stamps what it forwards
                at = None if ts is None else ts.get_time().timestamp()
                self._put(Received(k, env.sender, env.seq, env.stamp_s, msg, payload, at))
            except DecodeError as e:
                self.rejected += 1
                self._warn(k, f"rejected message on {k}: {e}")
            except Exception:  # never let a callback die silently
                log.exception("handling a message on %s failed", k)

        self._handles.append(self.session.declare_subscriber(key, on_sample))

    def subscribe_raw(
        self, key: str, decode_fn: Callable[[bytes], tuple[float, Message] | None]
    ) -> None:
        """Queue messages of a foreign format (ROS 2 CDR): ``decode_fn`` turns the bytes
        into (stamp, message), or None when it used them itself (nothing is queued), or
        raises DecodeError (counted and logged)."""
        seq = iter(range(1 << 62))

        def on_sample(sample: zenoh.Sample) -> None:
            k = str(sample.key_expr)
            try:
                got = decode_fn(sample.payload.to_bytes())
                if got is not None:
                    self._put(Received(k, "ros", next(seq), got[0], got[1]))
            except DecodeError as e:
                self.rejected += 1
                self._warn(k, f"rejected message on {k}: {e}")
            except Exception:
                log.exception("handling a message on %s failed", k)

        self._handles.append(self.session.declare_subscriber(key, on_sample))

    def inject(self, key: str, stamp_s: float, msg: Message) -> None:
        """Queue a message that arrived by another way than Zenoh (a ROS 2 node's)."""
        self._put(Received(key, "ros2-node", next(self._injected), stamp_s, msg))

    def put_raw(
        self, key: str, data: bytes, reliable: bool = False, attachment: bytes | None = None
    ) -> int:
        """Send bytes of a foreign format (ROS 2 CDR); returns their size."""
        self._publisher(key, reliable).put(data, attachment=attachment)
        n = len(data) + (len(attachment) if attachment else 0)
        self.bytes_sent[key] = self.bytes_sent.get(key, 0) + n
        return n

    def watch_alive(self, key: str) -> None:
        """Queue liveliness changes under ``key`` (see ``is_alive_change``)."""

        def on_sample(sample: zenoh.Sample) -> None:
            self._put(
                Received(
                    str(sample.key_expr), "", 0, 0.0, _Alive(sample.kind == zenoh.SampleKind.PUT)
                )
            )

        self._handles.append(
            self.session.liveliness().declare_subscriber(key, on_sample, history=True)
        )

    def declare_alive(self, key: str):
        """A liveliness token on ``key``, alive until ``undeclare`` or the bus closes."""
        token = self.session.liveliness().declare_token(key)
        self._handles.append(token)
        return token

    def undeclare(self, handle) -> None:
        if handle in self._handles:
            self._handles.remove(handle)
            handle.undeclare()

    def _put(self, item: Received) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.rejected += 1
            self._warn("queue", "receive queue full: message dropped")

    def poll(self, timeout_s: float = 0.0, limit: int = 1000) -> list[Received]:
        """Messages received since the last call (waiting up to ``timeout_s`` for one)."""
        out = []
        try:
            out.append(
                self._queue.get(timeout=timeout_s) if timeout_s > 0 else self._queue.get_nowait()
            )
        except queue.Empty:
            return out
        while len(out) < limit:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                break
        return out

    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warning.get(key, -1e9) >= LOG_EVERY_S:
            self._last_warning[key] = now
            log.warning("%s", text)

    def close(self) -> None:
        for h in self._handles + list(self._publishers.values()):
            with contextlib.suppress(Exception):
                h.undeclare()
        self._handles.clear()
        self._publishers.clear()

    @property
    def total_bytes_sent(self) -> int:
        return sum(self.bytes_sent.values())


@dataclass(frozen=True)
class _Alive(Message):
    """Not on the wire: a liveliness change queued like a message."""

    TYPE = "alive"
    alive: bool


def is_alive_change(item: Received) -> bool | None:
    """For a liveliness item: True (appeared) or False (gone); None for messages."""
    return item.msg.alive if isinstance(item.msg, _Alive) else None


def stop_on_signals(hangup: bool = False) -> threading.Event:
    """An event set by SIGINT or SIGTERM (and SIGHUP if ``hangup``): a process's main loop
    stops cleanly on it. SIGINT is handled even where the shell ignores it (a job started
    in the background), so ``kill -INT`` stops such a process cleanly too."""
    stop = threading.Event()

    def handler(signum, frame) -> None:
        log.info("%s received: stopping", signal.Signals(signum).name)
        stop.set()

    signals = [signal.SIGINT, signal.SIGTERM] + ([signal.SIGHUP] if hangup else [])
    for sig in signals:
        signal.signal(sig, handler)
    return stop
