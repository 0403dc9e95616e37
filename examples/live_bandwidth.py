"""Record every payload on Zenoh during an exploration: bytes per key, per second, peak.

    polyswarm launch --robots 3 --out runs/live &      # note the endpoint in runs/live/config.toml
    python examples/live_bandwidth.py tcp/127.0.0.1:PORT 60

Zenoh's own framing is estimated as the key expression plus 16 bytes per message (a
data message header with sequence number and encoding; batching makes it smaller).
"""

from __future__ import annotations

import collections
import sys
import threading
import time

from agents.session import SessionSpec, open_session

FRAMING_BYTES = 16  # per message, besides the key expression (an estimate)


def main(endpoint: str, seconds: str = "60") -> None:
    count = collections.Counter()
    size = collections.Counter()
    peak = collections.Counter()
    lock = threading.Lock()

    def on_sample(sample) -> None:
        key, n = str(sample.key_expr), len(sample.payload.to_bytes())
        with lock:
            count[key] += 1
            size[key] += n
            peak[key] = max(peak[key], n)

    with open_session(SessionSpec.client(endpoint)) as session:
        sub = session.declare_subscriber("polyswarm/**", on_sample)
        time.sleep(float(seconds))
        sub.undeclare()
    dur = float(seconds)
    print(f"{'key':<48} {'msgs':>7} {'bytes':>10} {'B/s':>8} {'peak':>7} {'framing':>8}")
    for key in sorted(size):
        framing = count[key] * (len(key) + FRAMING_BYTES)
        print(
            f"{key:<48} {count[key]:>7} {size[key]:>10} {size[key] / dur:>8.0f} "
            f"{peak[key]:>7} {framing:>8}"
        )


if __name__ == "__main__":
    main(*sys.argv[1:])
