"""The end of a mission: every robot home, and the maps robots announced handed over
(one back from out of range, one that left before it was home)."""

from __future__ import annotations

from agents.coordinator import Coordinator
from protocols.messages import MissionState, Pose, RobotState, RobotStatus
from tests.conftest import coordinator, corridor_map, feed


def home_with_nothing_left() -> Coordinator:
    """One robot, a corridor explored to its end, the robot home."""
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=False), 0.1)
    c.now = 1.0
    c.cycle()
    c._end_exploration([c.robots["r1"]])
    home = c.robots["r1"].assignment
    c.on_status("r1", c.now, RobotStatus(RobotState.HOME, home.target))
    return c


def test_the_mission_is_not_done_while_a_robot_back_in_range_has_not_handed_over_its_map():
    """Home, but its poses announce a map version the coordinator has not received (it
    mapped while out of range): the mission ends once that map is here."""
    c = home_with_nothing_left()
    have = c.robots["r1"].map.version
    c.on_pose("r1", c.now, Pose(1.0, 1.0, 0.0, have + 5))  # mapped on its own meanwhile
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.RETURNING
    later = corridor_map(open_end=False)
    c.on_robot_map("r1", type(later)(later.cell_size, later.cells, have + 5))  # fetched whole
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.DONE


def test_a_map_that_never_arrives_holds_the_end_of_the_mission_only_so_long():
    from agents.coordinator import HANDOVER_WAIT_S

    c = home_with_nothing_left()
    c.on_pose("r1", c.now, Pose(1.0, 1.0, 0.0, c.robots["r1"].map.version + 5))
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.RETURNING
    c.now += HANDOVER_WAIT_S
    c.cycle()
    assert c.state == MissionState.DONE


def test_a_robot_out_of_range_before_it_was_home_holds_the_end_of_the_mission():
    """r2 left (cut off while exploring): the mission waits for it; back in range with
    what it mapped alone, it hands it over and the mission ends."""
    from agents.coordinator import OUT_OF_RANGE_WAIT_S

    c = home_with_nothing_left()
    c.on_alive("r2", True)
    c.on_pose("r2", c.now, Pose(3.0, 1.0, 0.0, 0))
    c.on_alive("r2", False)  # out of range, not home
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.RETURNING
    c.now += OUT_OF_RANGE_WAIT_S / 2
    c.cycle()
    assert c.state == MissionState.RETURNING
    c.on_alive("r2", True)  # back in range: its map is fetched, then handed over
    c.cycle()  # a cycle between its liveliness and its first pose (office seed 0 ended here)
    assert c.state == MissionState.RETURNING
    c.on_pose("r2", c.now, Pose(3.0, 1.0, 0.0, 4))
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.RETURNING  # r2's map not here yet
    later = corridor_map(open_end=False)
    c.on_robot_map("r2", type(later)(later.cell_size, later.cells, 4))
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.DONE


def test_a_robot_that_never_comes_back_holds_the_end_only_so_long(caplog):
    from agents.coordinator import OUT_OF_RANGE_WAIT_S

    c = home_with_nothing_left()
    c.on_alive("r2", True)
    c.on_pose("r2", c.now, Pose(3.0, 1.0, 0.0, 0))
    c.on_alive("r2", False)
    left = c.now
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.RETURNING
    c.now = left + OUT_OF_RANGE_WAIT_S
    c.cycle()
    assert c.state == MissionState.DONE
    assert "without the last updates of r2" in caplog.text
