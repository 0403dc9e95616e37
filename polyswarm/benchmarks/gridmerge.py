"""The peer method, as a benchmark baseline only: feature-based occupancy-grid merging as
``multirobot_map_merge`` (m-explore) does it.

Its ``combine_grids`` pipeline, reproduced with the same OpenCV classes and defaults:
each robot's occupancy grid is taken as an 8-bit image (unknown -1 -> 255, free 0,
occupied 100), features (AKAZE, which ``map_merge`` hard-codes in ROS 1 and ROS 2, or
ORB, its other choice; OpenCV defaults), ``AffineBestOf2NearestMatcher``
(partial affine, match confidence 0.3, 6 matches at least), ``leaveBiggestComponent`` at
the confidence threshold (``estimation_confidence``, 1.0 by default), then
``AffineBasedEstimator`` and ``BundleAdjusterAffinePartial``. Our maps are rasterised at
5 cm into such grids.

Needs ``opencv-python-headless`` (a development dependency).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from PIL import Image, ImageDraw

from polyswarm.polymap import GridPolyMap, VectorType

GRID_RESOLUTION_M = 0.05  # the occupancy grids the peer method merges
UNKNOWN, FREE, OCCUPIED = 255, 0, 100  # int8 -1 / 0 / 100 read as uint8
MATCH_CONFIDENCE = 0.3  # AffineBestOf2NearestMatcher's default
MIN_MATCHES = 6  # its num_matches_thresh1 default
# the matcher asks each keypoint for its 2 nearest neighbours (the ratio test): an image
# with fewer keypoints makes OpenCV throw (a TurtleBot3's first 5 s of map had one each)
MIN_KEYPOINTS = 2
DEFAULT_THRESHOLD = 1.0  # map_merge's estimation_confidence default


@dataclass(frozen=True)
class GridMatch:
    pose: np.ndarray | None  # B's frame in A's (x m, y m, theta rad), None if no estimate
    confidence: float  # the pair's confidence (inliers / (8 + 0.3 matches))
    scale: float  # the partial affine's scale (1 for a rigid estimate)


def occupancy_image(pmap: GridPolyMap) -> tuple[np.ndarray, np.ndarray]:
    """The map as an 8-bit occupancy image (row = y) and its origin (m)."""
    x0, y0, x1, y1 = pmap.bounds()
    lo = np.array([x0, y0]) - 0.5
    w = math.ceil((x1 + 0.5 - lo[0]) / GRID_RESOLUTION_M)
    h = math.ceil((y1 + 0.5 - lo[1]) / GRID_RESOLUTION_M)
    img = Image.new("L", (w, h), UNKNOWN)
    draw = ImageDraw.Draw(img)

    def px(xy: np.ndarray) -> list[tuple[float, float]]:
        return [tuple(v) for v in ((xy - lo) / GRID_RESOLUTION_M).tolist()]

    polys = sorted(pmap.dissolve(0.01), key=lambda p: -abs(p.shell.signed_area))
    for p in polys:
        for k, ring in enumerate(p.rings()):
            if len(ring) >= 3:
                draw.polygon(px(ring.xy), fill=FREE if k == 0 else UNKNOWN)
    s, e, _ = pmap.vectors([VectorType.OBSTACLE])
    for a, b in zip(px(s), px(e), strict=True):
        draw.line([a, b], fill=OCCUPIED, width=3)
    return np.asarray(img, dtype=np.uint8).copy(), lo


class Features(StrEnum):
    AKAZE = "akaze"
    ORB = "orb"


def match_grids(a: GridPolyMap, b: GridPolyMap, features: Features = Features.AKAZE) -> GridMatch:
    """m-explore's estimate of B's frame in A's, from the maps as occupancy grids."""
    import cv2

    ia, lo_a = occupancy_image(a)
    ib, lo_b = occupancy_image(b)
    finder = cv2.AKAZE.create() if features == Features.AKAZE else cv2.ORB.create()
    feats = []
    for k, img in enumerate((ia, ib)):
        f = cv2.detail.computeImageFeatures2(finder, img)
        f.img_idx = k
        feats.append(f)
    if min(len(f.keypoints) for f in feats) < MIN_KEYPOINTS:
        return GridMatch(None, 0.0, 0.0)  # nothing to match (OpenCV's matcher would throw)
    matcher = cv2.detail.AffineBestOf2NearestMatcher(False, False, MATCH_CONFIDENCE, MIN_MATCHES)
    pairwise = matcher.apply2(feats)
    matcher.collectGarbage()
    confidence = float(pairwise[1].confidence)  # the pair (0, 1)
    if confidence <= 0:
        return GridMatch(None, confidence, 0.0)
    ok, cams = cv2.detail.AffineBasedEstimator().apply(feats, pairwise, None)
    if not ok:
        return GridMatch(None, confidence, 0.0)
    for c in cams:
        c.R = c.R.astype(np.float32)
    adjuster = cv2.detail.BundleAdjusterAffinePartial()
    adjuster.setConfThresh(min(confidence, DEFAULT_THRESHOLD) * 0.999)
    ok_ba, refined = adjuster.apply(feats, pairwise, cams)
    if ok_ba:
        cams = refined
    # B's pixels to A's: R_b^-1 R_a (the stitching module's convention; checked on maps
    # moved by known poses in tests/test_mapmatch.py)
    try:
        h = np.linalg.inv(cams[1].R.astype(float)) @ cams[0].R.astype(float)
    except np.linalg.LinAlgError:  # a degenerate estimate: no frame
        return GridMatch(None, confidence, 0.0)
    # metric: x = lo + res * px, so B metric -> A metric = S_a H S_b^-1
    s_a = np.array([[GRID_RESOLUTION_M, 0, lo_a[0]], [0, GRID_RESOLUTION_M, lo_a[1]], [0, 0, 1]])
    s_b = np.array([[GRID_RESOLUTION_M, 0, lo_b[0]], [0, GRID_RESOLUTION_M, lo_b[1]], [0, 0, 1]])
    m = s_a @ h @ np.linalg.inv(s_b)
    scale = float(math.hypot(m[0, 0], m[1, 0]))
    pose = np.array([m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])])
    return GridMatch(pose, confidence, scale)
