"""PolyMap deltas against occupancy-grid updates on one CARMEN log, side by side.

    python examples/bandwidth_from_log.py ../shared/data/logs/freiburg-101-corrected.log.gz

Writes a CSV of every update and a plot next to the log's name in runs/bandwidth/.
(``polyswarm bench bandwidth`` does this for every log and a simulated run.)
"""

from __future__ import annotations

import sys
from pathlib import Path

from polyswarm.benchmarks import bandwidth as bw
from polyswarm.config import Config


def main(log: str, out: str = "runs/bandwidth") -> None:
    rec = bw.record_log(Path(log), Config())
    res = bw.measure(rec)
    bw.write_outputs(res, Path(out))
    c = res["cumulative_bytes"]
    for scheme in bw.SCHEMES:
        print(f"{scheme:>20}: {bw.fmt_bytes(c[scheme])}")
    print(f"PolyMap deltas / best grid deltas: {res['delta_bytes_ratio_vs_best_grid']:.3f}")
    print(f"final PolyMap / grid PNG: {res['map_bytes_ratio_vs_png']:.2f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
