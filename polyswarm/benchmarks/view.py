"""``polyswarm bench view``: what the live view costs and how far behind it is.

Two ``polyswarm launch`` runs of the same world, robots, seed and wall-clock length, one
after the other: without the view, and with ``--view`` and a headless Chromium page
(Debian's, driven by Playwright) open on it for the whole run. Measured:

* ``display_latency_p95_ms``: from a merged delta's publication (the Zenoh router's
  timestamp as it forwards the delta) to the page drawing it (the page's wall clock
  after the next animation frame; one machine, one clock);
* ``view_cpu_share``: the view process's processor time over its wall time (all its
  threads: Zenoh, decoding, SVG, the web server);
* the coordinator's cycle p95 (all its work) in both runs, side by side.
"""

from __future__ import annotations

import json
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

BROWSER_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
CHROMIUM = "/usr/bin/chromium"


def wait_http(url: str, timeout_s: float) -> bool:
    """Does ``url`` answer within ``timeout_s``?"""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=1.0):
                return True
        except OSError:
            time.sleep(0.3)
    return False


def _run(opts, with_page: bool):
    from polyswarm.runners.launch import launch

    if not with_page:
        return launch(opts), None
    from playwright.sync_api import sync_playwright

    result: dict = {}
    runner = threading.Thread(target=lambda: result.update(r=launch(opts)))
    runner.start()
    url = f"http://127.0.0.1:{opts.view_port}/"
    if wait_http(url, 120.0):
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.goto(url)
            runner.join()
            browser.close()
    runner.join()
    res = result["r"]
    stats = res.out / "logs" / "view.json"
    return res, json.loads(stats.read_text()) if stats.exists() else None


def run(robots: int, world: str, duration_s: float, seed: int = 0) -> dict:
    from polyswarm.runners.children import free_port
    from polyswarm.runners.launch import LaunchOptions

    out = {"robots": robots, "world": world, "duration_s": duration_s, "seed": seed}
    with tempfile.TemporaryDirectory() as d:
        for name, port in (("without_view", None), ("with_view", free_port())):
            opts = LaunchOptions(
                world=world,
                robots=robots,
                seed=seed,
                wall_limit_s=duration_s,
                out=Path(d) / name,
                view_port=port,
            )
            res, view = _run(opts, port is not None)
            m = res.metrics
            out[name] = {
                "coordinator_cycle_p95_ms": m["coordinator_cycle_p95_ms"],
                "coordinator_cycle_cpu_p95_ms": m["coordinator_cycle_cpu_p95_ms"],
                "final_coverage": m["final_coverage"],
                "sim_time_s": m["sim_time_s"],
                "stopped_because": m["stopped_because"],
            }
            if view is not None:
                out["view"] = view
    v = out.get("view") or {}
    out["display_latency_p95_ms"] = v.get("display_latency_p95_ms")
    out["view_cpu_share"] = v.get("cpu_share")
    return out
