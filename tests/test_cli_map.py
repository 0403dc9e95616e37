"""The real ``polyswarm`` command as a subprocess on small inputs."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from polyswarm.io.mapserver import write_map


def run(*args, check=True, cwd=None):
    p = subprocess.run(
        [sys.executable, "-m", "polyswarm", *args],
        capture_output=True,
        check=False,
        text=True,
        cwd=cwd,
        timeout=300,
    )
    if check and p.returncode != 0:
        raise AssertionError(f"exit {p.returncode}: {p.stderr}")
    return p


@pytest.fixture
def small_world(tmp_path):
    d = np.full((40, 60), UNKNOWN, dtype=np.int8)
    d[5:35, 5:55] = OCCUPIED
    d[6:34, 6:54] = FREE
    d[15:25, 20:22] = OCCUPIED  # a wall stub
    d[6:34, 53] = UNKNOWN  # an open side: frontier
    path = tmp_path / "world.yaml"
    write_map(OccupancyGrid(d, 0.1, (-1.0, -2.0)), path)
    return path


def test_version_and_help():
    assert run("--version").stdout.startswith("polyswarm ")
    out = run("--help").stdout
    for cmd in ("map", "bench"):
        assert cmd in out


def test_convert_info_export(small_world, tmp_path):
    pm = tmp_path / "m.polymap"
    run("map", "convert", str(small_world), "-o", str(pm), "--cell-size", "1.0")
    assert pm.stat().st_size > 0
    info = run("map", "info", str(pm)).stdout
    assert "obstacle vectors" in info and "explored area" in info
    assert "12.96 m2" in info  # 28 x 47 free cells of 0.1 m minus the 10 x 2 stub
    for suffix in (".svg", ".png", ".geojson", ".yaml"):
        out = tmp_path / f"m{suffix}"
        run("map", "export", str(pm), "-o", str(out), "--grid", "--sectors")
        assert out.stat().st_size > 0
    gj = json.loads((tmp_path / "m.geojson").read_text())
    kinds = {f["properties"]["kind"] for f in gj["features"]}
    assert {"explored", "obstacle", "frontier", "sector"} <= kinds
    import shapely.geometry

    polys = [
        shapely.geometry.shape(f["geometry"])
        for f in gj["features"]
        if f["properties"]["kind"] == "explored"
    ]
    assert sum(p.area for p in polys) == pytest.approx(12.96)
    assert (tmp_path / "m.pgm").exists()


def test_known_errors_are_one_line_and_exit_1(tmp_path):
    p = run("map", "info", str(tmp_path / "missing.polymap"), check=False)
    assert p.returncode == 1
    assert p.stderr.strip().startswith("error:") and len(p.stderr.strip().splitlines()) == 1
    bad = tmp_path / "bad.polymap"
    bad.write_bytes(b"\x00\x01garbage")
    p = run("map", "info", str(bad), check=False)
    assert p.returncode == 1 and "error:" in p.stderr
    p = run("map", "export", str(bad), "-o", str(tmp_path / "x.bmp"), check=False)
    assert p.returncode == 1


def test_files_and_values_a_user_gets_wrong_end_in_one_line(small_world, tmp_path):
    pm = tmp_path / "m.polymap"
    run("map", "convert", str(small_world), "-o", str(pm), "--cell-size", "1.0")
    for args in (
        ("map", "export", str(pm), "-o", str(tmp_path / "missing" / "dir" / "x.yaml")),
        ("slam", "--world", "rooms", "-o", str(pm)),  # a file where a folder goes
        ("fleet-config", "--robots", "r1,r1", "--out", str(tmp_path / "fleet")),
    ):
        p = run(*args, check=False)
        assert p.returncode == 1, args
        last = p.stderr.strip().splitlines()[-1]  # (pybullet prints its build time first)
        assert last.startswith("error:") and "Traceback" not in p.stderr, args
    p = run(
        "map", "export", str(pm), "-o", str(tmp_path / "x.yaml"), "--resolution", "0", check=False
    )
    assert p.returncode == 2 and "--resolution" in p.stderr and "Traceback" not in p.stderr


def test_log_lines_go_to_standard_error():
    # `bench ... --json` prints its JSON on standard output; a warning logged during the
    # run (the 10-robot load test logs some) must not land in it
    # (an info line: without our handler, logging's last resort would print only
    # warnings, and without the logger's name)
    code = (
        "import logging; from polyswarm.cli import setup_logging; "
        "setup_logging(logging.INFO); logging.getLogger('polyswarm.x').info('a log line')"
    )
    p = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True, timeout=60
    )
    assert "polyswarm.x: a log line" in p.stderr
    assert p.stdout == ""


def test_slam_on_a_log_without_raw_odometry_says_how_to_run_it(tmp_path):
    """A log with only the anchoring ODOM lines has no real odometry: a one-line error
    that names the option (not a traceback, not synthetic noise unasked)."""
    lines = []
    for k in range(4):
        pose = f"{k} 0 0"
        lines.append(f"FLASER 3 1.0 2.0 3.0 {pose} {pose} {k + 1} h {k + 1}")
        lines.append(f"ODOM {pose} 0 0 0 1 h 1")
    log = tmp_path / "anchors.log"
    log.write_text("\n".join(lines) + "\n")
    p = run("slam", str(log), "-o", str(tmp_path / "out"), check=False)
    assert p.returncode == 1
    assert p.stderr.strip().startswith("error:") and "--odometry noise" in p.stderr
