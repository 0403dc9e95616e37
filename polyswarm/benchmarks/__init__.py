"""Benchmarks behind ``polyswarm bench NAME``: each returns a JSON-ready dict.

Part of the command layer: may use ``protocols``, ``sim`` and ``agents``. Timings are
medians and percentiles measured side by side in one run.
"""
