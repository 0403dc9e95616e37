"""A markdown table of `polyswarm bench explore --json` results (the README's).

python examples/explore_table.py docs/results/explore-*.json
"""

from __future__ import annotations

import json
import sys


def fmt(x, digits: int = 1) -> str:
    return "never" if x is None else f"{x:,.{digits}f}"


def rows(result: dict):
    s = result.get("summary", result)
    for prof, worlds in s["profiles"].items():
        for world, by_n in worlds.items():
            for n, c in sorted(by_n.items()):
                yield prof, world, n, c


def main(paths: list[str]) -> None:
    print(
        "| profile | world | robots | t99 per seed (s) | median (reference) | ratio: median, worst"
        " | success | unexplored reachable, worst | IoU, worst |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for path in paths:
        with open(path) as f:
            result = json.load(f)
        for prof, world, n, c in rows(result):
            seeds = ", ".join(fmt(t) for t in c["t99_s"])
            ratio = c["t99_ratio_vs_reference"]
            worst = c["t99_ratio_vs_reference_worst"]
            print(
                f"| {prof} | {world} | {n} | {seeds} | {fmt(c['t99_median_s'])} s"
                f" ({fmt(c['reference_t99_s'])} s) | {fmt(ratio, 2)}, {fmt(worst, 2)}"
                f" | {c['success_rate']:.0%} | {c['unexplored_reachable_m2_max']:.1f} m2"
                f" | {c['map_iou_min']:.3f} |"
            )


if __name__ == "__main__":
    main(sys.argv[1:])
