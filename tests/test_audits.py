"""The frame of a robot merged on a frame found here is audited: a merge contradicted
later is undone, one the sightings and maps agree with is kept."""

from __future__ import annotations

import numpy as np
import pytest

from polyswarm.config import Config
from polyswarm.frames.mapmatch import transform_map
from polyswarm.polymap import GridPolyMap
from polyswarm.se2 import compose, inverse, transform_points
from tests.conftest import anchoring_ticks


def _handed_over(frame_sent):
    """r1 mapped the west of the building (the shared frame); r2, whose start ``truth``
    puts at (4 m, -3 m), the east in its own frame. r2 is anchored at ``frame_sent``
    (committed as it is) and handed over: (anchoring, main coordinator, truth, the
    merged area before r2, r2's map as moved)."""
    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from tests.conftest import seen_map

    truth = np.array([4.0, -3.0, 2.1])
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", seen_map(box(-1, -8, 16, 9)))
    main.on_alive("r1", True)
    main.flush()
    area = main.merged.explored_area()
    frames = Anchoring(cfg, ["r2"])
    b = seen_map(box(8, -8, 25, 9), truth)
    frames.owner("r2", main).on_robot_map("r2", b)
    frames.waiting["r2"].frames.pose = np.asarray(frame_sent, dtype=float)  # committed
    [(rid, anchor)] = frames.tick(main, 0.0)
    assert rid == "r2" and anchor.frame == 1 and not anchor.own
    moved = transform_map(b, frame_sent)
    moved = GridPolyMap(moved.cell_size, moved.cells, b.version + 1)
    frames.owner("r2", main).on_robot_map("r2", moved)  # (the anchor's correction)
    main.now = 1.0
    assert frames.on_pose("r2", 1, moved.version, main)
    main.flush()
    assert main.merged.explored_area() > 1.2 * area  # r2's map joined the merged map
    return frames, main, truth, area, moved


@pytest.mark.parametrize("sightings", [True, False], ids=["sightings", "maps alone"])
def test_a_merge_contradicted_later_is_undone_and_the_frame_found_again(sightings, caplog):
    """r2's frame is committed 3 m off (as ``launch --wrong-anchor`` does) and its map
    merged. Afterwards r1 sees r2 where r2 really is, not where that frame puts it (2.5 m
    from r1, in its clear view), and r2's map's walls stand in r1's explored space;
    either undoes the merge. r2's cells leave the merged map (its solo coordinator keeps
    them: nothing is lost), it is sent an ``own`` anchor and waits again in the
    coordinates it speaks in; the next matches and sightings anchor it right (anchor 3:
    the true frame, seen from those coordinates)."""
    from agents.anchoring import RESEND_S
    from agents.audits import UNDO_AUDITS, UNDO_CONTRADICTIONS
    from protocols.messages import Pose
    from tests.conftest import profile_with_a_robot_at

    truth = np.array([4.0, -3.0, 2.1])
    wrong = compose(truth, np.array([3.0, 0.0, 0.0]))
    frames, main, truth, area, moved = _handed_over(wrong)
    caplog.set_level("INFO", logger="agents.anchoring")
    for k in range(UNDO_CONTRADICTIONS + 4 if sightings else 0):  # r1 sees r2 at the truth
        clear = profile_with_a_robot_at(truth[:2])
        frames.sighted("r1", 2.0 + k, Pose(0.0, 0.0, 0.0, clear=clear))
        frames.sighted("r2", 2.0 + k, Pose(*wrong, frame=1))
    sent, now = anchoring_ticks(frames, main, 2.0, lambda: frames.undone > 0)
    assert frames.undone == 1, "the audit did not undo the merge"
    if not sightings:  # one audit's conflicts are not trusted
        assert f"earlier ones in {UNDO_AUDITS} audits in a row: merge undone" in caplog.text
    else:  # with its evidence: r1 at the origin looked where the frame put r2
        x, y = wrong[:2]
        assert f"r1 at (0.00, 0.00) saw clear where the frame put r2: ({x:.2f}, {y:.2f})" in (
            caplog.text
        )
    [(rid, release)] = sent
    assert rid == "r2" and release.own and release.frame == 2
    assert (release.x, release.y, release.theta) == (0.0, 0.0, 0.0)
    assert "r2" not in main.robots and "r2" in frames.waiting
    main.flush()
    assert abs(main.merged.explored_area() - area) < 0.01 * area  # its cells left
    solo = frames.owner("r2", main)
    assert solo is not main
    assert solo.robots["r2"].map.explored_area() == moved.explored_area()  # nothing lost
    # sent again until its poses name it; they do not hand it over
    assert frames.tick(main, now + RESEND_S) == [("r2", release)]
    assert not frames.on_pose("r2", 2, moved.version, main)
    assert frames.waiting["r2"].release is None
    # found again: seen from r2's coordinates now (the wrong frame's), the true frame is
    again = compose(truth, inverse(wrong))
    t0 = now + 10.0
    for k in range(7):  # r2 drives past r1, who sees it (as in ``_see_each_other``)
        there = truth[:2] + 0.6 * np.array([min(k, 3), -max(k - 3, 0)])
        mine = transform_points(inverse(again), there[None])[0]
        clear = profile_with_a_robot_at(there)
        frames.sighted("r1", t0 + k, Pose(0.0, 0.0, 0.0, clear=clear))
        frames.sighted("r2", t0 + k, Pose(*mine, 0.0, frame=2))
    sent, _ = anchoring_ticks(frames, main, t0 + 7, lambda: frames.waiting["r2"].anchor is not None)
    [(rid, anchor)] = sent
    assert anchor.frame == 3 and not anchor.own
    assert np.hypot(anchor.x - again[0], anchor.y - again[1]) < 0.05
    assert abs(anchor.theta - again[2]) < 0.01
    frames.close()


def test_a_merge_the_sightings_agree_with_is_audited_and_kept():
    """The same hand-over at the true frame; r1 sees r2 where that frame puts it, at
    every moment: the audits run and find nothing against it (no moment, no wall in
    r1's clear space)."""
    from protocols.messages import Pose
    from tests.conftest import profile_with_a_robot_at

    frames, main, truth, _, _ = _handed_over(np.array([4.0, -3.0, 2.1]))
    for k in range(30):
        frames.sighted("r1", 2.0 + k, Pose(0.0, 0.0, 0.0, clear=profile_with_a_robot_at(truth[:2])))
        frames.sighted("r2", 2.0 + k, Pose(*truth, frame=1))
    audit = frames.audits["r2"]
    runs = []

    def three_audits() -> bool:
        if audit.running is not None and audit.running not in runs:
            runs.append(audit.running)
        return len(runs) >= 3 and all(r.done() for r in runs)

    anchoring_ticks(frames, main, 2.0, three_audits, wall_s=60.0)
    assert len(runs) >= 3
    assert all(r.result()[0] == [] and r.result()[1] < 0.01 < r.result()[2] for r in runs)
    assert frames.undone == 0 and "r2" in main.robots and "r2" not in frames.waiting
    frames.close()


def test_a_right_frame_is_held_against_maps_not_in_doubt_not_a_wrong_one_before_it():
    """r2 was merged 3 m off, r3 right, after it. r3's audit holds its map against r1's
    (the first robot: its frame is not in doubt), not r2's: no conflict. r2's own audit
    finds most of its shared walls in r1's clear space."""
    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.audits import UNDO_CONFLICT_SHARE, Audit
    from agents.coordinator import Coordinator, RobotInfo
    from tests.conftest import seen_map

    truth = np.array([4.0, -3.0, 2.1])
    wrong = compose(truth, np.array([3.0, 0.0, 0.0]))
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", seen_map(box(-1, -8, 16, 9)))
    frames = Anchoring(cfg, ["r2", "r3"])
    east = seen_map(box(8, -8, 25, 9), truth)  # in the robots' own frames
    for rid, frame, since_s in (("r2", wrong, 1.0), ("r3", truth, 2.0)):
        del frames.waiting[rid]
        main.robots[rid] = RobotInfo(rid, frame)
        main.robots[rid].map = transform_map(east, frame)
        frames.audits[rid] = Audit(1, since_s)
    n3, share3, overlap3 = frames._audit_evidence("r3", frames.audits["r3"], main)()
    n2, share2, overlap2 = frames._audit_evidence("r2", frames.audits["r2"], main)()
    assert n2 == n3 == []  # no sightings: no moments against either
    assert share3 < 0.01 and overlap3 > 10.0
    assert share2 > UNDO_CONFLICT_SHARE and overlap2 > 10.0
    frames.close()
