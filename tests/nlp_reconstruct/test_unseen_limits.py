"""Joint limits at the ends of a joint's seen span (stop_limits with ``seen``): an end the joint
only takes while moving into the frames nobody saw is no observed stop."""

import numpy as np
import pytest

from kinemaforge_opt.nlp.reconstruction import stop_limits

T = np.linspace(0.0, 3.0, 31)  # 10 Hz frames [s]


def door(t):
    """A door pushed open at 1 rad/s that coasts to rest at 1.2 rad by 2 s (q [rad] at t [s])."""
    return np.where(t < 1.0, t, 1.0 + 0.2 * (1.0 - (2.0 - np.minimum(t, 2.0)) ** 2))


def test_an_end_first_seen_while_moving_off_it_moves_out_by_the_reach_of_the_unseen_time():
    q = door(T)[:, None]
    seen = (T >= 0.5)[:, None]  # the part is first seen 0.5 s into the push
    lower, upper = stop_limits(T, q, seen)[0]
    # fastest frame step 1 rad/s, unseen for 0.5 s: the door can have been up to 0.5 rad lower
    assert lower == pytest.approx(0.5 - 1.0 * 0.5, abs=1e-9)
    assert upper == pytest.approx(1.2, abs=1e-9)  # reached and rested at while seen: kept


def test_an_end_last_seen_while_arriving_moves_out_and_seen_ends_are_kept():
    q = door(T)[:, None]
    seen = (T <= 0.8 + 1e-9)[:, None]  # lost 0.8 s in, still being pushed open
    lower, upper = stop_limits(T, q, seen)[0]
    assert lower == pytest.approx(0.0, abs=1e-9)  # seen from the first frame: the observed start
    assert upper == pytest.approx(0.8 + 1.0 * (3.0 - 0.8), abs=1e-9)
    # seen throughout, or first seen at rest: the observed range, as without a mask
    np.testing.assert_allclose(stop_limits(T, q), [[0.0, 1.2]], atol=1e-9)
    np.testing.assert_allclose(stop_limits(T, q, (T >= 2.5)[:, None]), [[1.2, 1.2]], atol=1e-9)


def test_unseen_values_are_ignored_and_joints_are_masked_one_by_one():
    q = np.column_stack([door(T), 0.05 * T])  # a door and a drawer sliding at 0.05 m/s
    q[:5, 0] = np.nan  # the door's track starts at frame 5
    limits = stop_limits(T, q)  # default mask: where q is finite
    assert limits[0] == pytest.approx([0.5 - 0.5, 1.2], abs=1e-9)
    assert limits[1] == pytest.approx([0.0, 0.15], abs=1e-9)


def test_a_joint_whose_part_is_never_seen_keeps_the_range_of_its_values():
    q = door(T)[:, None]
    np.testing.assert_allclose(stop_limits(T, q, np.zeros((T.size, 1), dtype=bool)), [[0.0, 1.2]], atol=1e-9)


def test_unseen_frames_carry_the_first_and_last_seen_speed_within_the_limits():
    from kinemaforge_opt.nlp.reconstruction import unseen_carried_on

    q = door(T)[:, None]
    seen = ((T >= 0.3 - 1e-9) & (T <= 0.8 + 1e-9))[:, None]
    held = np.where(T < 0.3, 0.3, np.where(T > 0.8, 0.8, q[:, 0]))[:, None]  # as the NLP holds them
    carried = unseen_carried_on(T, held, seen, np.array([[0.1, 1.0]]))
    # 1 rad/s at both ends of the seen span: back to 0.1 (the lower limit) and on to 1.0
    np.testing.assert_allclose(carried[:, 0], np.clip(T, 0.1, 1.0), atol=1e-9)
    np.testing.assert_array_equal(carried[seen[:, 0]], held[seen[:, 0]])  # seen frames untouched
