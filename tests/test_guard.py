"""The last check on a command to a real base (polyswarm/nav/guard.py), by hand."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from polyswarm.nav.guard import guard, in_the_way

R = 0.105  # a TurtleBot3


def test_a_return_just_ahead_stops_the_robot_and_one_beside_its_path_does_not():
    ahead = np.array([[R + 0.01, 0.0]])
    beside = np.array([[R + 0.01, R + 0.01]])  # clear of its body's corridor
    assert guard(0.2, 0.5, ahead, R, 0.02, 0.22, 2.0) == (0.0, 0.5)  # turning stays allowed
    assert guard(0.2, 0.5, beside, R, 0.02, 0.22, 2.0) == (0.2, 0.5)
    assert guard(-0.1, 0.0, ahead, R, 0.02, 0.22, 2.0) == (-0.1, 0.0)  # backing away is fine


def test_the_body_is_round_a_point_off_the_centre_line_counts_from_its_edge():
    # at y = 0.08 the front edge is sqrt(0.105^2 - 0.08^2) = 0.068 m ahead of the centre
    y = 0.08
    edge = math.sqrt(R**2 - y**2)
    assert in_the_way(np.array([[edge + 0.019, y]]), R, 0.02, forward=True)
    assert not in_the_way(np.array([[edge + 0.021, y]]), R, 0.02, forward=True)


def test_speed_limits_clamp_the_command():
    assert guard(1.0, -9.0, np.zeros((0, 2)), R, 0.02, 0.22, 2.0) == (0.22, -2.0)


@settings(max_examples=100, deadline=None)
@given(
    st.floats(-1.0, 1.0),
    st.floats(-3.0, 3.0),
    st.lists(st.tuples(st.floats(-2, 2), st.floats(-2, 2)), max_size=20),
)
def test_never_faster_and_never_towards_a_return_in_the_way(v, w, pts):
    xy = np.array(pts, dtype=float).reshape(-1, 2)
    gv, gw = guard(v, w, xy, R, 0.05, 0.3, 1.5)
    assert abs(gv) <= 0.3 and abs(gw) <= 1.5
    if gv != 0.0:
        assert not in_the_way(xy, R, 0.05, forward=gv > 0)
