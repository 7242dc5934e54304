"""Joint limits at the ends of a joint's seen span (stop_limits with ``seen``): an end the joint
only takes while moving into the frames nobody saw is no observed stop."""

import numpy as np
import pytest

from kinemaforge_opt.nlp.reconstruction import unseen_carried_on
from kinemaforge_opt.stops import stop_limits

T = np.linspace(0.0, 3.0, 31)  # 10 Hz frames [s]


def door(t):
    """A door sent open at 2.4 rad/s that slows evenly to rest at 1.2 rad at 1 s (q [rad] at t [s])."""
    return 1.2 * (1.0 - (1.0 - np.minimum(t, 1.0)) ** 2)


def test_an_end_first_seen_while_slowing_off_it_moves_out_by_the_first_steps_reach():
    q = door(T)[:, None]
    seen = (T >= 0.5 - 1e-9)[:, None]  # first seen 0.5 s into the swing
    lower, upper = stop_limits(T, q, seen)[0]
    first_speed = (door(0.6) - door(0.5)) / 0.1  # 1.08 rad/s, then 0.84
    assert lower == pytest.approx(door(0.5) - first_speed * 0.5, abs=1e-9)
    assert upper == pytest.approx(1.2, abs=1e-9)  # reached and rested at while seen: kept


def test_an_end_left_speeding_up_or_steadily_may_be_where_it_started():
    # a drawer first seen as it is pulled out from rest there: its first pose may be its stop
    q = np.where(T < 1.0, 0.0, 0.2 * (T - 1.0) ** 2)[:, None]
    seen = (T >= 1.0 - 1e-9)[:, None]
    np.testing.assert_allclose(stop_limits(T, q, seen), [[0.0, 0.8]], atol=1e-9)
    # pulled at a steady speed, its second step 1 % slower (noise): kept too
    q = np.where(T < 1.0, 0.0, 0.28 * (T - 1.0) - 0.0003 * (T > 1.15))[:, None]
    np.testing.assert_allclose(stop_limits(T, q, seen)[0, 0], 0.0, atol=1e-9)


def test_an_end_last_seen_arriving_faster_moves_out_and_seen_ends_are_kept():
    q = (0.5 * T**2)[:, None]  # speeding up
    seen = (T <= 0.8 + 1e-9)[:, None]  # lost 0.8 s in
    lower, upper = stop_limits(T, q, seen)[0]
    assert lower == pytest.approx(0.0, abs=1e-9)  # seen from the first frame
    assert upper == pytest.approx(0.5 * 0.64 + 0.5 * (0.64 - 0.49) / 0.1 * 2.2, abs=1e-9)
    # arriving slower at its last seen frame (the door coming to rest): kept
    np.testing.assert_allclose(stop_limits(T, door(T)[:, None], (T <= 0.8 + 1e-9)[:, None]), [[0.0, door(0.8)]], atol=1e-9)
    # seen throughout: the observed range, as without a mask
    np.testing.assert_allclose(stop_limits(T, door(T)[:, None]), [[0.0, 1.2]], atol=1e-9)


def test_unseen_values_are_ignored_and_joints_are_masked_one_by_one():
    q = np.column_stack([door(T), 0.05 * T])  # a door and a drawer sliding at 0.05 m/s
    q[:5, 0] = np.nan  # the door's track starts at frame 5
    limits = stop_limits(T, q)  # default mask: where q is finite
    assert limits[0] == pytest.approx([door(0.5) - (door(0.6) - door(0.5)) / 0.1 * 0.5, 1.2], abs=1e-9)
    assert limits[1] == pytest.approx([0.0, 0.15], abs=1e-9)


def test_a_joint_whose_part_is_never_seen_keeps_the_range_of_its_values():
    q = door(T)[:, None]
    np.testing.assert_allclose(stop_limits(T, q, np.zeros((T.size, 1), dtype=bool)), [[0.0, 1.2]], atol=1e-9)


def test_unseen_frames_carry_the_first_and_last_seen_speed_within_the_limits():
    q = np.clip(T, 0.0, 1.0)[:, None]  # 1 rad/s until it rests at 1 rad
    seen = ((T >= 0.3 - 1e-9) & (T <= 0.8 + 1e-9))[:, None]
    held = np.where(T < 0.3, 0.3, np.where(T > 0.8, 0.8, q[:, 0]))[:, None]  # as the NLP holds them
    carried = unseen_carried_on(T, held, seen, np.array([[0.1, 1.0]]))
    # 1 rad/s at both ends of the seen span: back to 0.1 (the lower limit) and on to 1.0
    np.testing.assert_allclose(carried[:, 0], np.clip(T, 0.1, 1.0), atol=1e-9)
    np.testing.assert_array_equal(carried[seen[:, 0]], held[seen[:, 0]])  # seen frames untouched
