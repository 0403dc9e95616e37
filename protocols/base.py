"""The base of every message: ``Message``, its ``Envelope``, ``ProtocolError`` (the one
error type of a bad message: nothing else escapes a decoder) and the checks of fields
from the network (each returns the value or raises ``ProtocolError``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, ClassVar

from polyswarm.errors import DecodeError
from polyswarm.frames.sighting import SECTORS

MAX_TEXT = 256  # characters of a free-text field


class ProtocolError(DecodeError):
    """A message from the network is malformed (refused whole; nothing is applied)."""


@dataclass(frozen=True)
class Envelope:
    type: str
    version: int
    sender: str
    seq: int
    stamp_s: float


class Message:
    """Base of the message types: ``TYPE`` names it on the wire."""

    TYPE: ClassVar[str]

    def body(self) -> dict:
        raise NotImplementedError

    @classmethod
    def from_body(cls, b: dict) -> Message:
        raise NotImplementedError


def number(v: Any, name: str, lo: float = -1e9, hi: float = 1e9) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ProtocolError(f"field {name!r}: expected a number")
    v = float(v)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ProtocolError(f"field {name!r}: {v} is not within [{lo}, {hi}]")
    return v


def integer(v: Any, name: str, lo: int = -(2**62), hi: int = 2**62) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not (lo <= v <= hi):
        raise ProtocolError(f"field {name!r}: expected an integer in [{lo}, {hi}]")
    return v


def text(v: Any, name: str, choices: type[StrEnum] | None = None) -> str:
    if not isinstance(v, str) or len(v) > MAX_TEXT:
        raise ProtocolError(f"field {name!r}: expected a string of at most {MAX_TEXT} chars")
    if choices is not None:
        try:
            return choices(v)
        except ValueError:
            raise ProtocolError(f"field {name!r}: {v!r} is not one of {list(choices)}") from None
    return v


def blob(v: Any, name: str, max_len: int) -> bytes:
    if not isinstance(v, bytes) or len(v) > max_len:
        raise ProtocolError(f"field {name!r}: expected at most {max_len} bytes")
    return v


def clear_sectors(v: Any) -> bytes:
    v = blob(v, "clr", SECTORS)
    if v and len(v) != SECTORS:
        raise ProtocolError(f"field 'clr': expected {SECTORS} bytes, got {len(v)}")
    return v


def xy(v: Any, name: str) -> tuple[float, float]:
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise ProtocolError(f"field {name!r}: expected [x, y]")
    return (number(v[0], name), number(v[1], name))


def points(v: Any, name: str, max_n: int = 4096) -> tuple[tuple[float, float], ...]:
    if not isinstance(v, list | tuple) or len(v) > max_n:
        raise ProtocolError(f"field {name!r}: expected a list of at most {max_n} points")
    return tuple(xy(p, name) for p in v)
