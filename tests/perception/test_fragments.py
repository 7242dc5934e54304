"""Fragments of a part that slide along themselves (perception.track.merge_fragments): a drawer's
side wall whose track lags joins the drawer whose motion the images accept for it; a second
drawer moving at other times is no explanation.  The images are an exact oracle of the true
scene (a carcass hides what is inside it; outside it, space off the true surfaces is seen
through)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kinemaforge_opt.perception.track import (ICP_FINE_VOXELS, Proposal, Tracker, absorb, explained_by, explained_in_pieces,
                                              merge_fragments, static_explains)
from kinemaforge_opt.spatial import transform_points

STEPS = 16
CARCASS = (np.array([-0.2, 0.0, 0.0]), np.array([0.2, 0.4, 0.6]))  # box [m]; drawers pull along -y
ON_SURFACE = 0.002  # [m] a point this close to a true surface point is confirmed
MIN_POINTS = 100  # the smallest part: a sixth of a front


def _grid(x, y, z) -> np.ndarray:
    """Points on the grid spanned by three 1-D coordinate arrays [m], (N, 3)."""
    return np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1).reshape(-1, 3)


def _drawer(z0: float) -> tuple[np.ndarray, np.ndarray]:
    """(front, left side wall) points [m] of a drawer shut in the carcass, bottom at height z0."""
    z = np.linspace(z0, z0 + 0.15, 16)
    front = _grid(np.linspace(-0.19, 0.19, 39), [0.0], z)
    wall = _grid([-0.18], np.linspace(0.01, 0.39, 39), z)
    return front, wall


def _stroke(start: int) -> np.ndarray:
    """(STEPS,) opening [m] of a drawer pulled 3 cm per step over 8 steps from ``start``."""
    return 0.03 * np.clip(np.arange(STEPS) - start, 0, 8)


def _motion(y: np.ndarray, ref: int) -> np.ndarray:
    """(STEPS, 4, 4) world motion from step ``ref`` of a pull by y [m] along -y."""
    Ts = np.tile(np.eye(4), (STEPS, 1, 1))
    Ts[:, 1, 3] = -(y - y[ref])
    return Ts


class _Oracle(Tracker):
    """verify() against the true surfaces at each step: confirmed on a surface; seen through off
    them outside the carcass; neither (hidden) inside it."""

    def __init__(self, surfaces: list[np.ndarray]):
        self.trees = [cKDTree(s) for s in surfaces]
        self.voxel = ON_SURFACE / ICP_FINE_VOXELS  # the fine ICP radius: a point on a surface
        self.min_points = MIN_POINTS

    def verdicts(self, points, s):
        on = self.trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        inside = np.all((points > CARCASS[0]) & (points < CARCASS[1]), axis=1)
        return on.astype(int), (~on & ~inside).astype(int)

    def verify(self, points, s):
        on, seen_through = self.verdicts(points, s)
        return float(np.mean(on)), float(np.mean(seen_through))

    def full_tree(self, s):
        return self.trees[s]  # the observed surfaces are the true ones


def _scene():
    """Two drawers: A (bottom) opens over steps 0-8, B (above) over steps 8-16; proposals: both
    fronts tracked truly, A's side wall with a track that lags at half the stroke."""
    (fa, wa), (fb, wb) = _drawer(0.05), _drawer(0.3)
    ya, yb = _stroke(0), _stroke(8)
    shift = lambda pts, y: pts - np.array([0.0, y, 0.0])
    surfaces = [np.concatenate([shift(fa, a), shift(wa, a), shift(fb, b), shift(wb, b)]) for a, b in zip(ya, yb)]
    ref = 4
    props = [Proposal("front_a", ref, shift(fa, ya[ref]), _motion(ya, ref)),
             Proposal("front_b", 12, shift(fb, yb[12]), _motion(yb, 12)),
             Proposal("wall_a", ref, shift(wa, ya[ref]), _motion(0.5 * ya, ref))]
    return _Oracle(surfaces), props, wa, ya


def test_a_lagging_side_wall_joins_its_drawer_and_not_the_other_one():
    oracle, (front_a, front_b, wall_a), wall_true, ya = _scene()
    assert explained_by(oracle, wall_a, [front_a, front_b, wall_a]) == (0, 4, [])
    # the other drawer's motion puts the wall in the air in front of the carcass
    assert explained_by(oracle, wall_a, [front_b, wall_a]) == (None, None, [])
    merged = merge_fragments(oracle, [front_a, front_b, wall_a])
    assert [p.name for p in merged] == ["front_a", "front_b"]
    a = merged[0]
    np.testing.assert_array_equal(a.Ts_delta, front_a.Ts_delta)  # the drawer's motion is kept
    # the wall's points sit where the true wall is at the drawer's reference step
    np.testing.assert_allclose(a.points[len(front_a.points):], wall_true - [0.0, ya[4], 0.0], atol=1e-12)


def test_fronts_moving_at_different_times_explain_each_other_never():
    oracle, (front_a, front_b, _), _, _ = _scene()
    assert explained_by(oracle, front_a, [front_a, front_b]) == (None, None, [])
    assert explained_by(oracle, front_b, [front_a, front_b]) == (None, None, [])
    # nor does a lagging track explain the front it lags behind
    lag = Proposal("lag", 4, front_a.points, _motion(0.5 * _stroke(0), 4))
    assert explained_by(oracle, front_a, [front_a, lag]) == (None, None, [])


def test_absorb_carries_points_through_the_anchor_step():
    ya = _stroke(0)
    part = Proposal("p", 2, np.zeros((1, 3)), _motion(ya, 2))
    frag = Proposal("f", 6, np.array([[0.0, 0.0, 0.0]]), _motion(ya, 6))  # one point, at step 6
    out = absorb(_Oracle([np.zeros((1, 3))] * STEPS), part, frag, 6)
    # the point at step 6 is at the origin; the part moved by ya[6] - ya[2] between its reference and 6
    np.testing.assert_allclose(out.points[1], [0.0, ya[6] - ya[2], 0.0], atol=1e-12)


def test_absorb_fills_the_steps_only_the_fragment_reached_where_the_images_accept_them():
    """Drawer A's front tracked from step 4 lost steps 0-2 (a face seen only later, as a door's
    inner side); its side wall, tracked truly at every step, is absorbed: the front's track takes
    the wall's motion at those steps, as the true one.  Where the wall's own track is wrong (6 cm
    up at step 1), the images refuse the merged points there and the step stays unobserved; the
    steps the front did observe keep its motion."""
    oracle, (front_a, _, _), wall_true, ya = _scene()
    lost = front_a.Ts_delta.copy()
    lost[:3] = np.nan
    front = Proposal("front_a", 4, front_a.points, lost)
    wall = Proposal("wall", 4, wall_true - [0.0, ya[4], 0.0], _motion(ya, 4))
    out = absorb(oracle, front, wall, 4)
    np.testing.assert_allclose(out.Ts_delta, front_a.Ts_delta, atol=1e-12)
    wrong = wall.Ts_delta.copy()
    wrong[1, 2, 3] += 0.06
    out = absorb(oracle, front, Proposal("wall", 4, wall.points, wrong), 4)
    assert np.isnan(out.Ts_delta[1]).all()
    np.testing.assert_allclose(out.Ts_delta[[0, 2]], front_a.Ts_delta[[0, 2]], atol=1e-12)
    np.testing.assert_array_equal(out.Ts_delta[3:], front_a.Ts_delta[3:])


def test_absorb_replaces_a_failed_pose_with_the_fragments_and_keeps_the_others():
    """Drawer A's front tracked 5 cm too far out at step 6 (pulled along by a neighbour): there its
    merged points with the truly tracked side wall fit the images far worse than at its other
    steps, and the wall's pose fits them: the track takes the wall's pose at step 6 and keeps its
    own elsewhere.  A wall whose track lags keeps the front's true track whole (no step of it
    failed)."""
    oracle, (front_a, _, wall_a), wall_true, ya = _scene()
    off = front_a.Ts_delta.copy()
    off[6, 1, 3] -= 0.05
    front = Proposal("front_a", 4, front_a.points, off)
    wall = Proposal("wall", 4, wall_true - [0.0, ya[4], 0.0], _motion(ya, 4))
    np.testing.assert_allclose(absorb(oracle, front, wall, 4).Ts_delta, front_a.Ts_delta, atol=1e-12)
    np.testing.assert_array_equal(absorb(oracle, front_a, wall_a, 4).Ts_delta, front_a.Ts_delta)


def test_a_part_track_that_fails_at_one_step_still_explains_its_wall_and_loses_that_step():
    """The drawer's own track jumps 6 cm up at one step of 16 (a glitch the tracker let through):
    the wall's points land in the air there, so that step is unobserved after the merge."""
    oracle, (front_a, front_b, wall_a), _, _ = _scene()
    Ts = front_a.Ts_delta.copy()
    Ts[6, 2, 3] += 0.06
    glitchy = Proposal("front_a", front_a.ref, front_a.points, Ts)
    assert explained_by(oracle, wall_a, [glitchy, front_b, wall_a]) == (0, 4, [6])
    merged = merge_fragments(oracle, [glitchy, front_b, wall_a])
    assert [p.name for p in merged] == ["front_a", "front_b"]
    assert np.isnan(merged[0].Ts_delta[6]).all()
    keep = np.arange(STEPS) != 6
    np.testing.assert_array_equal(merged[0].Ts_delta[keep], front_a.Ts_delta[keep])


def test_a_drawer_that_differs_at_two_steps_only_is_not_absorbed_by_another():
    """Drawers A and B pulled together over steps 0-8, then B alone 6 cm further at each of steps
    14 and 15: A's well-tracked motion puts B's front in the air at those two steps (2 of 16,
    within a track's allowance for failures), which no failure of A's track excuses."""
    ya = _stroke(0)
    yb = ya + 0.06 * np.clip(np.arange(STEPS) - 13, 0, 2)
    fa, fb = _drawer(0.05)[0], _drawer(0.3)[0]
    oracle = _Oracle([np.concatenate([fa - [0.0, a, 0.0], fb - [0.0, b, 0.0]]) for a, b in zip(ya, yb)])
    front_a = Proposal("a", 4, fa - [0.0, ya[4], 0.0], _motion(ya, 4))
    front_b = Proposal("b", 4, fb - [0.0, yb[4], 0.0], _motion(yb, 4))
    assert explained_by(oracle, front_b, [front_a, front_b]) == (None, None, [])


def test_a_drawer_panel_carried_into_the_carcass_by_another_drawer_is_not_its_fragment():
    """Drawer A opens over steps 0-8 and stays open; B opens over 8-16.  B's back panel, tracked
    truly over B's stroke, carried by A's motion instead (at rest then) stays inside the carcass:
    hidden, so nothing contradicts it, but confirmed at B's reference step only, where its own
    motion is confirmed at every step.  The images tell the two motions apart: no fragment."""
    fa, fb = _drawer(0.05)[0], _drawer(0.3)[0]
    back_b = _grid(np.linspace(-0.19, 0.19, 39), [0.38], np.linspace(0.3, 0.45, 16))
    ya, yb = _stroke(0), _stroke(8)
    shift = lambda pts, y: pts - np.array([0.0, y, 0.0])
    oracle = _Oracle([np.concatenate([shift(fa, a), shift(fb, b), shift(back_b, b)]) for a, b in zip(ya, yb)])
    front_a = Proposal("front_a", 4, shift(fa, ya[4]), _motion(ya, 4))
    Ts = _motion(yb, 12)
    Ts[:8] = np.nan  # the panel is seen only once B moves
    panel = Proposal("back_b", 12, shift(back_b, yb[12]), Ts)
    assert explained_by(oracle, panel, [front_a, panel]) == (None, None, [])
    assert [p.name for p in merge_fragments(oracle, [front_a, panel])] == ["front_a", "back_b"]


def test_a_fragment_of_two_drawers_walls_is_split_between_them():
    """One proposal holds A's side wall and B's (stacked above it), tracked with a lag of half A's
    stroke: neither drawer's motion explains it whole (each puts the other's wall in the air), so
    it is explained in pieces.  A's wall goes to A whole; B's wall, a flat surface that slides
    along itself under any pull, goes to B or A wherever the images cannot tell, and the fragment
    is gone."""
    (fa, wa), (fb, wb) = _drawer(0.05), _drawer(0.3)
    ya, yb = _stroke(0), _stroke(8)
    shift = lambda pts, y: pts - np.array([0.0, y, 0.0])
    oracle = _Oracle([np.concatenate([shift(fa, a), shift(wa, a), shift(fb, b), shift(wb, b)]) for a, b in zip(ya, yb)])
    front_a = Proposal("front_a", 4, shift(fa, ya[4]), _motion(ya, 4))
    front_b = Proposal("front_b", 12, shift(fb, yb[12]), _motion(yb, 12))
    mix = Proposal("mix", 4, np.concatenate([shift(wa, ya[4]), shift(wb, yb[4])]), _motion(0.5 * ya, 4))
    props = [front_a, front_b, mix]
    assert explained_by(oracle, mix, props) == (None, None, [])
    pieces = explained_in_pieces(oracle, mix, props)
    by_a = np.concatenate([piece.points for k, piece, _, _ in pieces if k == 0])
    assert {tuple(p) for p in shift(wa, ya[4])} <= {tuple(p) for p in by_a}  # A's wall, all of it
    for k, piece, _, _ in pieces:
        if k != 0:  # nothing of A's wall elsewhere
            assert np.all(piece.points[:, 2] > 0.25)
    merged = merge_fragments(oracle, props)
    assert [p.name for p in merged] == ["front_a", "front_b"]
    assert len(merged[0].points) >= len(fa) + len(wa)


def test_a_body_strip_whose_track_wandered_is_the_bases_and_a_briefly_open_drawer_is_not():
    """A strip of the carcass's top, tracked sliding 1 cm a step along itself (nothing contradicts
    it left in place, which the images confirm as often), is the base's: merged away.  A drawer
    front open at two steps of sixteen, its shut place hidden in the carcass then, is contradicted
    nowhere in place either, but only its motion confirms it at those steps: it stays."""
    top = _grid(np.linspace(-0.19, 0.19, 20), np.linspace(0.02, 0.38, 19), [0.6])
    fa = _drawer(0.05)[0] + [0.0, 0.005, 0.0]  # flush with the carcass: hidden once pulled out
    ya = 0.1 * np.isin(np.arange(STEPS), [6, 7])
    oracle = _Oracle([np.concatenate([top, fa - [0.0, a, 0.0]]) for a in ya])
    Ts = np.tile(np.eye(4), (STEPS, 1, 1))
    Ts[:, 1, 3] = 0.01 * (np.arange(STEPS) - 4)
    strip = Proposal("strip", 4, top[np.abs(top[:, 1] - 0.2) < 0.1], Ts)
    front = Proposal("front", 4, fa, _motion(ya, 4))
    assert static_explains(oracle, strip)
    assert not static_explains(oracle, front)
    assert [p.name for p in merge_fragments(oracle, [front, strip])] == ["front"]


class _RangeOracle(_Oracle):
    """The exact oracle with a depth test whose tolerance grows with range, as a real camera's
    does: a point in the open less than FLOOR_TOLERANCE above the floor in front of the carcass
    is confirmed by the floor reading behind it.  Drawer B, once pulled out by ``b_out`` [m] (per
    step), hides what lies under it from the cameras above."""

    FLOOR_TOLERANCE = 0.1  # [m]

    def __init__(self, surfaces: list[np.ndarray], b_out: np.ndarray):
        super().__init__(surfaces)
        self.b_out = b_out

    def verdicts(self, points, s):
        on = self.trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        inside = np.all((points > CARCASS[0]) & (points < CARCASS[1]), axis=1)
        x, y, z = points.T
        under_b = (y > -self.b_out[s]) & (y < 0.0) & (np.abs(x) < 0.19) & (z < 0.3)
        hidden = inside | under_b
        confirmed = ~hidden & (on | ((z <= self.FLOOR_TOLERANCE) & (y < 0.0)))
        return confirmed.astype(int), (~hidden & ~confirmed).astype(int)


def test_a_drawers_floor_joins_its_drawer_though_the_floor_confirms_the_other_drawers_motion():
    """Drawer A's floor, tracked with a lag of half A's stroke, is a fragment.  Carried by B's motion
    (B above, pulled over steps 8-16) it lies in the open just above the ground, where a range-sized
    depth tolerance confirms it at every step; carried by A's own motion it is hidden under B once B
    is out.  Both motions leave it uncontradicted; A's puts it on observed surfaces (Tracker.fit's
    test), B's does not, and A takes it in either order of the proposals (ranked by the free-space
    shares alone, B took it: protocol_drawer_0's lower drawer lost its floor to the upper one).
    Tracked truly, the floor is no fragment of B's at all (judged by the free-space shares, the
    ground's tolerance made B's motion nearly as good as its own, and B took it)."""
    (fa, _), (fb, _) = _drawer(0.05), _drawer(0.3)
    floor_a = _grid(np.linspace(-0.17, 0.17, 18), np.linspace(0.01, 0.39, 24), [0.05])  # 3 cm strokes miss its rows
    ground = _grid(np.linspace(-0.4, 0.4, 81), np.linspace(-0.6, 0.0, 61), [0.0])
    ya, yb = _stroke(0), _stroke(8)
    shift = lambda pts, y: pts - np.array([0.0, y, 0.0])
    surfaces = [np.concatenate([ground, shift(fa, a), shift(floor_a, a), shift(fb, b)]) for a, b in zip(ya, yb)]
    oracle = _RangeOracle(surfaces, yb)
    front_a = Proposal("front_a", 4, shift(fa, ya[4]), _motion(ya, 4))
    front_b = Proposal("front_b", 12, shift(fb, yb[12]), _motion(yb, 12))
    floor = Proposal("floor_a", 6, shift(floor_a, ya[6]), _motion(0.5 * ya, 6))
    assert explained_by(oracle, floor, [front_b, floor]) == (0, 6, [])  # B alone would do
    # tracked truly and seen from cameras B does not block, the floor is on observed surfaces
    # wherever it is seen, and B's motion puts it on almost none (the ground's tolerance takes it):
    # no fragment of B's
    tracked = Proposal("floor_a", 6, floor.points, _motion(ya, 6))
    assert explained_by(_RangeOracle(surfaces, np.zeros(STEPS)), tracked, [front_b, tracked]) == (None, None, [])
    assert explained_by(oracle, floor, [front_a, front_b, floor]) == (0, 6, [])
    assert explained_by(oracle, floor, [front_b, front_a, floor]) == (1, 6, [])
    merged = merge_fragments(oracle, [front_a, front_b, floor])
    assert [(p.name, len(p.points)) for p in merged] == [("front_a", len(fa) + len(floor_a)), ("front_b", len(fb))]


class _HidingOracle(_Oracle):
    """The oracle with the carcass hiding what is inside it from confirmation too: a shut drawer's
    side wall is neither confirmed nor seen through."""

    def verdicts(self, points, s):
        on = self.trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        inside = np.all((points > CARCASS[0]) & (points < CARCASS[1]), axis=1)
        return (on & ~inside).astype(int), (~on & ~inside).astype(int)


def test_a_wall_tracked_onto_another_drawers_front_while_its_own_is_shut_joins_its_drawer():
    """The front half of A's side wall (hidden in the carcass while A is shut, steps 0-8) is
    tracked rightly while A opens, but at the shut steps its track lies on B's front (a
    re-detection onto another drawer, turned a quarter turn): a surface, so its own motion puts it
    on surfaces there and A's does not.  That surface is B's, held by B's larger proposal: it
    witnesses neither motion."""
    (fa, wa), (fb, wb) = _drawer(0.05), _drawer(0.3)
    ya, yb = _stroke(8), _stroke(0)  # A opens over steps 8-16, B over 0-8
    shift = lambda pts, y: pts - np.array([0.0, y, 0.0])
    surfaces = [np.concatenate([shift(fa, a), shift(wa, a), shift(fb, b), shift(wb, b)]) for a, b in zip(ya, yb)]
    oracle = _HidingOracle(surfaces)
    ref = 12
    front_a = Proposal("front_a", ref, shift(fa, ya[ref]), _motion(ya, ref))
    front_b = Proposal("front_b", 4, shift(fb, yb[4]), _motion(yb, 4))
    track = _motion(ya, ref)
    for s in range(9):  # the shut wall (x = -0.18) turned onto B's front: (x, y, z) -> (y - 0.2, -x - 0.18 - yb, z + 0.25)
        onto_b = np.array([[0.0, 1.0, 0.0, -0.2], [-1.0, 0.0, 0.0, -0.18 - yb[s]], [0.0, 0.0, 1.0, 0.25], [0.0, 0.0, 0.0, 1.0]])
        track[s] = onto_b @ _motion(ya, ref)[s]
        np.testing.assert_allclose(cKDTree(shift(fb, yb[s])).query(transform_points(track[s], shift(wa, ya[ref])))[0], 0.0,
                                   atol=1e-9)  # on B's front indeed
    wall = Proposal("wall_a", ref, shift(wa, ya[ref])[: len(wa) // 2], track)  # its front half
    assert explained_by(oracle, wall, [front_a, front_b, wall]) == (0, ref, [])
    # with nothing holding B's front, the wall's own motion puts it on a surface A's does not
    assert explained_by(oracle, wall, [front_a, wall]) == (None, None, [])
    assert [p.name for p in merge_fragments(oracle, [front_a, front_b, wall])] == ["front_a", "front_b"]
