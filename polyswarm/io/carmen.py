"""CARMEN log reader: FLASER, ROBOTLASER1 and ODOM lines (``.gz`` accepted).

``#`` comments, PARAM lines (kept as parameters) and unknown message types are
skipped; a malformed known line raises ``DataFormatError`` with its line number.

FLASER beams are assumed to span 180 degrees unless a PARAM says otherwise
(``laser_front_laser_fov`` or ``robot_front_laser_fov``; CARMEN writes radians, and a
value above 2 pi is read as degrees); with an odd beam count
the first and last beam sit on the edges of the field of view, with an even count the
beams are ``fov / n`` apart. Readings at or beyond the maximum range (the PARAM
``robot_front_laser_max``, else the largest reading in the log) mean "no return".
Timestamps are the log's own when they increase; otherwise (some logs print them
with too few digits, or as zeros) they are synthesized as scan index times
``SYNTH_PERIOD_S`` and the log says so.
"""

from __future__ import annotations

import gzip
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyswarm.errors import DataFormatError
from polyswarm.slam.scan import LaserScan

SYNTH_PERIOD_S = 1.0  # the logs keep only the scans a grid SLAM used: about 1 per second
DEFAULT_FOV_DEG = 180.0


@dataclass(frozen=True, eq=False)
class CarmenScan:
    index: int
    line: int
    stamp: float
    scan: LaserScan
    pose: np.ndarray  # the pose on the laser line (for the corrected logs: the reference)
    odom: np.ndarray  # the odometry pose on the laser line


@dataclass(frozen=True, eq=False)
class CarmenLog:
    path: str
    scans: list[CarmenScan]
    odometry: np.ndarray  # (k, 4) t x y theta from ODOM lines
    params: dict[str, str] = field(default_factory=dict)
    timestamps_synthesized: bool = False
    odometry_lines: np.ndarray | None = None  # (k,) line number of each ODOM line

    @property
    def reference(self) -> np.ndarray:
        return np.array([s.pose for s in self.scans])


def _open(path: Path):
    if path.suffix == ".gz":
        return gzip.open(path, "rt", errors="replace")
    return open(path, errors="replace")


def _floats(tokens: list[str], lineno: int, what: str) -> list[float]:
    try:
        vals = [float(t) for t in tokens]
    except ValueError as e:
        raise DataFormatError(f"line {lineno}: {what}: {e}") from None
    if not all(math.isfinite(v) for v in vals):
        raise DataFormatError(f"line {lineno}: {what}: non-finite number")
    return vals


def _count(token: str, lineno: int, what: str) -> int:
    try:
        n = int(token)
    except ValueError:
        raise DataFormatError(f"line {lineno}: {what}: bad count {token!r}") from None
    if n < 1 or n > 100_000:
        raise DataFormatError(f"line {lineno}: {what}: absurd count {n}")
    return n


def read_carmen(path: str | Path) -> CarmenLog:
    p = Path(path)
    if not p.exists():
        raise DataFormatError(f"log not found: {p}")
    params: dict[str, str] = {}
    raw = []  # (kind, lineno, ranges, angle_min, inc, pose, odom, stamp)
    odom = []
    try:
        with _open(p) as fh:
            for lineno, line in enumerate(fh, start=1):
                tok = line.split()
                if not tok or tok[0].startswith("#"):
                    continue
                kind = tok[0]
                if kind == "PARAM":
                    if len(tok) >= 3:
                        params[tok[1]] = tok[2]
                elif kind == "FLASER":
                    raw.append(_flaser(tok, lineno))
                elif kind == "ROBOTLASER1":
                    raw.append(_robotlaser(tok, lineno))
                elif kind == "ODOM":
                    if len(tok) < 8:
                        raise DataFormatError(
                            f"line {lineno}: ODOM needs 7 values, got {len(tok) - 1}"
                        )
                    x, y, th, *_ = _floats(tok[1:7], lineno, "ODOM")
                    t = _floats(tok[7:8], lineno, "ODOM timestamp")[0]
                    odom.append((t, x, y, th, lineno))
    except (OSError, EOFError, UnicodeDecodeError) as e:
        raise DataFormatError(f"{p}: cannot read: {e}") from e
    if not raw:
        raise DataFormatError(f"{p}: no FLASER or ROBOTLASER1 lines")
    fov_param = params.get("laser_front_laser_fov") or params.get("robot_front_laser_fov")
    try:
        fov = float(fov_param) if fov_param else math.radians(DEFAULT_FOV_DEG)
    except ValueError:
        raise DataFormatError(f"{p}: PARAM laser fov is not a number: {fov_param!r}") from None
    if fov > 2 * math.pi + 1e-6:
        fov = math.radians(fov)
    if "robot_front_laser_max" in params:
        range_max = float(params["robot_front_laser_max"])
    else:
        range_max = max(float(np.max(r[2])) for r in raw)
    stamps = np.array([r[7] for r in raw])
    steps = np.diff(stamps)
    synthesized = len(stamps) > 1 and (
        (steps <= 0).mean() > 0.1 or len(np.unique(stamps)) < 0.9 * len(stamps)
    )
    if synthesized:
        stamps = np.arange(len(raw)) * SYNTH_PERIOD_S
    scans = []
    for k, (kind, lineno, ranges, start, step, pose, od, _) in enumerate(raw):
        n = len(ranges)
        amin, inc = start, step
        if kind == "FLASER":
            inc = fov / (n - 1) if n % 2 == 1 else fov / n
            amin = -fov / 2
        scan = LaserScan(ranges, amin, inc, 0.05, range_max, float(stamps[k]))
        scans.append(CarmenScan(k, lineno, float(stamps[k]), scan, pose, od))
    od = np.array(odom, dtype=float).reshape(-1, 5)
    return CarmenLog(str(p), scans, od[:, :4], params, bool(synthesized), od[:, 4].astype(np.int64))


MAX_MISSING_ODOMETRY = 0.05  # share of scan steps without raw ODOM lines a log may have


def real_odometry(log: CarmenLog) -> np.ndarray:
    """The robot's real wheel odometry at every scan, chained from the first scan's pose
    (``../shared/data/README.md``): after each laser line an ODOM line re-anchors at the
    corrected pose, and the ODOM lines up to the next laser line integrate the raw wheel
    odometry from there, so the step to scan i is the motion from that anchor to the
    last ODOM pose before scan i. A step without raw ODOM lines repeats the previous
    step's motion. Raises DataFormatError when more than ``MAX_MISSING_ODOMETRY`` of the
    steps have none (orebro has only the anchors)."""
    from polyswarm.se2 import compose, relative

    lines = log.odometry_lines
    if lines is None or len(lines) == 0:
        raise DataFormatError(f"{log.path}: no ODOM lines (no real odometry)")
    poses = log.odometry[:, 1:4]
    scan_lines = np.array([s.line for s in log.scans])
    out = [np.array(log.scans[0].pose, dtype=float)]
    missing = 0
    last = np.zeros(3)
    for i in range(1, len(log.scans)):
        between = np.nonzero((lines > scan_lines[i - 1]) & (lines < scan_lines[i]))[0]
        if len(between) >= 2:
            last = relative(poses[between[0]], poses[between[-1]])
        else:
            missing += 1
        out.append(compose(out[-1], last))
    if missing > MAX_MISSING_ODOMETRY * max(len(log.scans) - 1, 1):
        raise DataFormatError(
            f"{log.path}: {missing} of {len(log.scans) - 1} scan steps have no raw ODOM "
            "lines (no real odometry: use synthetic noise)"
        )
    return np.array(out)


def _flaser(tok: list[str], lineno: int):
    if len(tok) < 2:
        raise DataFormatError(f"line {lineno}: FLASER without a beam count")
    n = _count(tok[1], lineno, "FLASER")
    need = 2 + n + 6 + 1
    if len(tok) < need:
        raise DataFormatError(
            f"line {lineno}: FLASER with {n} beams needs {need} fields, got {len(tok)}"
        )
    ranges = np.array(_floats(tok[2 : 2 + n], lineno, "FLASER ranges"))
    vals = _floats(tok[2 + n : 2 + n + 7], lineno, "FLASER pose")
    return ("FLASER", lineno, ranges, 0.0, 0.0, np.array(vals[0:3]), np.array(vals[3:6]), vals[6])


def _robotlaser(tok: list[str], lineno: int):
    # ROBOTLASER1 type start fov res max_range accuracy remission_mode n [ranges]
    #   n_rem [remissions] laser_x laser_y laser_th robot_x robot_y robot_th tv rv
    #   forward_safety side_safety turn_axis timestamp host logger_timestamp
    if len(tok) < 9:
        raise DataFormatError(f"line {lineno}: ROBOTLASER1 too short")
    head = _floats(tok[2:8], lineno, "ROBOTLASER1 header")
    start, fov, res = head[0], head[1], head[2]
    n = _count(tok[8], lineno, "ROBOTLASER1")
    i = 9 + n
    if len(tok) < i + 1:
        raise DataFormatError(f"line {lineno}: ROBOTLASER1 truncated in its ranges")
    ranges = np.array(_floats(tok[9:i], lineno, "ROBOTLASER1 ranges"))
    try:
        n_rem = int(tok[i])
    except ValueError:
        raise DataFormatError(f"line {lineno}: ROBOTLASER1 bad remission count") from None
    j = i + 1 + max(n_rem, 0)
    if len(tok) < j + 12:
        raise DataFormatError(f"line {lineno}: ROBOTLASER1 truncated after its ranges")
    vals = _floats(tok[j : j + 12], lineno, "ROBOTLASER1 poses")
    laser, robot, stamp = vals[0:3], vals[3:6], vals[11]
    inc = res if res > 0 else fov / max(n - 1, 1)
    return ("ROBOTLASER1", lineno, ranges, start, inc, np.array(laser), np.array(robot), stamp)
