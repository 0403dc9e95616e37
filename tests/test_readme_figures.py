"""Every figure in the README and docs/results.md comes from a committed result file.

A row of their tables ends in a cell like
```bandwidth.json#runs.{aces-corrected,csail-corrected}.delta_bytes_ratio_vs_keyframe_scans```
(braces expand to one key each; a ``*100`` suffix scales the values, for percentages);
its value cell lists the figures in the same order, as printed (``never`` for a missing
value). Each must equal the file's value rounded to the digits shown.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

from polyswarm.benchmarks.results import RESULTS_DIR, load, lookup

ROOT = Path(__file__).resolve().parents[1]
PAGES = (ROOT / "README.md", ROOT / "docs" / "results.md")
REF = re.compile(r"`([\w.-]+)\.json#([^`]+)`")
NUMBER = re.compile(r"never|-?\d[\d,]*(?:\.\d+)?")


def expand(key: str) -> list[str]:
    """``a.{b,c}.d`` -> ``a.b.d``, ``a.c.d`` (several braces: every combination)."""
    parts = re.split(r"\{([^}]*)\}", key)
    fixed, choices = parts[0::2], [p.split(",") for p in parts[1::2]]
    out = []
    for combo in itertools.product(*choices):
        s = fixed[0]
        for c, f in zip(combo, fixed[1:], strict=True):
            s += c + f
        out.append(s)
    return out


def headline_rows() -> list[tuple[str, str, str, str]]:
    """(row text, value cell, file name, key) of every table row naming a result."""
    rows = []
    for line in (line for page in PAGES for line in page.read_text().splitlines()):
        if not line.startswith("|"):
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        m = REF.search(cells[-1])
        if m and len(cells) >= 3:
            rows.append((cells[0], cells[1], m.group(1), m.group(2)))
    return rows


def test_the_pages_cite_committed_results_and_every_result_is_cited():
    rows = headline_rows()
    assert len(rows) >= 8
    cited = {name for _, _, name, _ in rows}
    assert cited == {p.stem for p in RESULTS_DIR.glob("*.json")}


def test_no_result_was_measured_on_uncommitted_code():
    for path in RESULTS_DIR.glob("*.json"):
        assert not load(path.stem)["meta"]["code_version"].endswith("-dirty"), path.name


@pytest.mark.parametrize("row", headline_rows(), ids=lambda r: r[0][:40])
def test_each_headline_figure_equals_its_result_file(row):
    what, shown, name, key = row
    result = load(name)
    assert "meta" in result, f"{name}.json has no meta (code version, processor, date)"
    key, _, factor = key.partition("*")
    scale = float(factor) if factor else 1.0
    keys = expand(key)
    printed = NUMBER.findall(shown)
    assert len(printed) == len(keys), f"{what}: {len(printed)} figures for {len(keys)} keys"
    for text, k in zip(printed, keys, strict=True):
        value = lookup(result, k)
        if text == "never":
            assert value is None, f"{what}: {k} is {value}, printed never"
            continue
        digits = len(text.split(".")[1]) if "." in text else 0
        assert value is not None, f"{what}: {k} is missing, printed {text}"
        assert round(scale * float(value), digits) == pytest.approx(float(text.replace(",", ""))), (
            f"{what}: {k} = {value}, printed {text}"
        )
