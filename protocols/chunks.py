"""Maps and map changes on the wire in parts: a payload larger than ``CHUNK_BYTES`` is
cut into ``MapChunk`` messages and reassembled by ``Reassembler`` (PROTOCOL.md 5.2)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import ClassVar

from protocols.base import Message, ProtocolError, blob, integer, text

CHUNK_BYTES = 32 * 1024  # map payload per message: well under Zenoh's 64 KB batches
MAX_MAP_BYTES = 64 * 1024 * 1024  # a reassembled map larger than this is refused


class MapKind(StrEnum):
    DELTA = "delta"  # a polymap-delta (PROTOCOL.md 3.3)
    MERGE = "merge"  # a polymap-merge (3.4): the keyframe polygon that changed the map
    CORRECT = "correct"  # a polymap-correct (3.5): keyframes a loop closure moved
    MAP = "map"  # a full polymap (3.2), the reply of a map queryable


# the type of an encoded map change (``protocols.mapcodec``) -> the MapChunk kind it goes in
MAP_KIND_OF = {
    "polymap-delta": MapKind.DELTA,
    "polymap-merge": MapKind.MERGE,
    "polymap-correct": MapKind.CORRECT,
}


@dataclass(frozen=True)
class MapChunk(Message):
    """Part ``part`` of ``parts`` of an encoded map or delta of ``total`` bytes.

    ``base``/``ver``: the delta applies to map version ``base`` and gives ``ver`` (a full
    map has base -1). ``stream`` is the sender's number for the payload, shared by its
    parts."""

    TYPE: ClassVar[str] = "map-chunk"
    kind: MapKind
    base: int
    ver: int
    stream: int  # identifies the payload among the sender's chunks
    part: int
    parts: int
    total: int
    data: bytes = field(repr=False)

    def body(self) -> dict:
        return {
            "kind": str(self.kind),
            "base": self.base,
            "ver": self.ver,
            "stream": self.stream,
            "part": self.part,
            "parts": self.parts,
            "total": self.total,
            "data": self.data,
        }

    @classmethod
    def from_body(cls, b: dict) -> MapChunk:
        ver = integer(b.get("ver"), "ver", 0)
        parts = integer(b.get("parts"), "parts", 1, MAX_MAP_BYTES // CHUNK_BYTES + 1)
        total = integer(b.get("total"), "total", 0, MAX_MAP_BYTES)
        data = blob(b.get("data"), "data", CHUNK_BYTES)
        part = integer(b.get("part"), "part", 0, parts - 1)
        if total > parts * CHUNK_BYTES:
            raise ProtocolError("total larger than its parts can hold")
        return cls(
            text(b.get("kind"), "kind", MapKind),
            integer(b.get("base"), "base", -1, ver),
            ver,
            integer(b.get("stream"), "stream", 0),
            part,
            parts,
            total,
            data,
        )


def chunk_payload(
    kind: MapKind, payload: bytes, base: int, ver: int, stream: int
) -> list[MapChunk]:
    """Cut an encoded map or delta into chunks of at most ``CHUNK_BYTES``."""
    if len(payload) > MAX_MAP_BYTES:
        raise ProtocolError(f"map payload of {len(payload)} bytes exceeds {MAX_MAP_BYTES}")
    parts = max(1, -(-len(payload) // CHUNK_BYTES))
    return [
        MapChunk(
            kind,
            base,
            ver,
            stream,
            k,
            parts,
            len(payload),
            payload[k * CHUNK_BYTES : (k + 1) * CHUNK_BYTES],
        )
        for k in range(parts)
    ]


@dataclass
class _Partial:
    first: MapChunk
    parts: dict[int, bytes]
    started_s: float


class Reassembler:
    """Collects map chunks per (sender, stream) into whole payloads.

    Incomplete payloads are dropped after ``timeout_s`` (of the caller's clock) and at
    most ``max_pending`` are kept; chunks that disagree with their stream's first chunk
    are refused. ``add`` returns the first chunk and the whole payload once complete."""

    def __init__(self, timeout_s: float = 10.0, max_pending: int = 16) -> None:
        self.timeout_s = timeout_s
        self.max_pending = max_pending
        self._pending: dict[tuple[str, int], _Partial] = {}

    def add(self, sender: str, chunk: MapChunk, now_s: float) -> tuple[MapChunk, bytes] | None:
        for key in [k for k, p in self._pending.items() if now_s - p.started_s > self.timeout_s]:
            del self._pending[key]
        if chunk.parts == 1:
            if len(chunk.data) != chunk.total:
                raise ProtocolError("single chunk does not hold its total")
            return chunk, chunk.data
        key = (sender, chunk.stream)
        p = self._pending.get(key)
        if p is None:
            if len(self._pending) >= self.max_pending:
                oldest = min(self._pending, key=lambda k: self._pending[k].started_s)
                del self._pending[oldest]
            p = self._pending[key] = _Partial(chunk, {}, now_s)
        f = p.first
        if (chunk.kind, chunk.base, chunk.ver, chunk.parts, chunk.total) != (
            f.kind,
            f.base,
            f.ver,
            f.parts,
            f.total,
        ):
            del self._pending[key]
            raise ProtocolError("chunk disagrees with the rest of its stream")
        expected = min(CHUNK_BYTES, chunk.total - chunk.part * CHUNK_BYTES)
        if len(chunk.data) != expected:
            del self._pending[key]
            raise ProtocolError(f"chunk {chunk.part} holds {len(chunk.data)} bytes, not {expected}")
        p.parts[chunk.part] = chunk.data
        if len(p.parts) < chunk.parts:
            return None
        del self._pending[key]
        return f, b"".join(p.parts[k] for k in range(chunk.parts))
