"""Unsigned LEB128 varints and zigzag integers, vectorised with numpy.

    encode_varints(np.array([1, 300])) == b"\\x01\\xac\\x02"
    decode_varints(b"\\x01\\xac\\x02") -> array([1, 300])

``decode_varints`` reads untrusted bytes: a truncated varint or one longer than
``MAX_VARINT_BYTES`` raises ``DecodeError``.
"""

from __future__ import annotations

import numpy as np

from polyswarm.errors import DecodeError

MAX_VARINT_BYTES = 9  # 63 bits: every value fits an int64 after decoding


def zigzag(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.int64)
    return ((v << 1) ^ (v >> 63)).astype(np.uint64)


def unzigzag(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=np.uint64)
    return ((u >> np.uint64(1)).astype(np.int64)) ^ (-((u & np.uint64(1)).astype(np.int64)))


def encode_varints(values: np.ndarray) -> bytes:
    v = np.asarray(values, dtype=np.uint64).ravel()
    if len(v) == 0:
        return b""
    if (v >= np.uint64(1) << np.uint64(63)).any():
        raise ValueError("varint value does not fit in 63 bits")
    nbytes = np.ones(len(v), dtype=np.int64)
    t = v >> np.uint64(7)
    while t.any():
        nbytes += t > 0
        t = t >> np.uint64(7)
    ends = np.cumsum(nbytes)
    out = np.empty(int(ends[-1]), dtype=np.uint8)
    starts = ends - nbytes
    for k in range(int(nbytes.max())):
        m = nbytes > k
        chunk = (v[m] >> np.uint64(7 * k)) & np.uint64(0x7F)
        more = (nbytes[m] > k + 1).astype(np.uint8) << 7
        out[starts[m] + k] = chunk.astype(np.uint8) | more
    return out.tobytes()


def decode_varints(data: bytes) -> np.ndarray:
    b = np.frombuffer(data, dtype=np.uint8)
    if len(b) == 0:
        return np.zeros(0, dtype=np.int64)
    last = (b & 0x80) == 0
    if not last[-1]:
        raise DecodeError("truncated varint at end of data")
    ends = np.nonzero(last)[0]
    starts = np.concatenate([[0], ends[:-1] + 1])
    lengths = ends - starts + 1
    if lengths.max() > MAX_VARINT_BYTES:
        raise DecodeError("varint longer than 63 bits")
    pos = np.arange(len(b)) - np.repeat(starts, lengths)
    shifted = (b & 0x7F).astype(np.uint64) << (7 * pos).astype(np.uint64)
    return np.bitwise_or.reduceat(shifted, starts).astype(np.int64)
