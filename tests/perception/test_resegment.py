"""Motion-consistent per-point segmentation (perception.resegment): the points of one proposal
that another known motion explains better move to it.  The images are an exact oracle of the true
scene (test_fragments' convention: a point on a true surface is confirmed; off them it is seen
through outside the carcass and hidden inside it), and each point's true part is known."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kinemaforge_opt.perception.resegment import resegment
from kinemaforge_opt.perception.track import Proposal, Tracker

STEPS = 16
VOXEL = 0.01  # [m]: the grids below are one voxel apart
CARCASS = (np.array([-0.2, 0.0, 0.0]), np.array([0.2, 0.4, 0.6]))  # box [m]; drawers pull along -y
ON_SURFACE = 0.008  # [m]: a cell centroid of the grid lies 0.71 voxel from its nearest point


def _front(z0: float) -> np.ndarray:
    """(N, 3) points [m] of a shut drawer's front (15 cm tall from z0, one voxel apart), y = 0."""
    g = np.meshgrid(np.arange(-0.19, 0.19 + 1e-9, VOXEL), [0.0], np.arange(z0, z0 + 0.15 - 1e-9, VOXEL), indexing="ij")
    return np.stack(g, axis=-1).reshape(-1, 3)


def _pull(y: np.ndarray, ref: int) -> np.ndarray:
    """(STEPS, 4, 4) world motion from step ``ref`` of a pull by y [m] along -y."""
    Ts = np.tile(np.eye(4), (STEPS, 1, 1))
    Ts[:, 1, 3] = -(y - y[ref])
    return Ts


def _stroke(start: int) -> np.ndarray:
    """(STEPS,) opening [m]: pulled 3 cm per step over 8 steps from ``start``."""
    return 0.03 * np.clip(np.arange(STEPS) - start, 0, 8)


class _Oracle(Tracker):
    """verdicts() from the true surfaces at each step; with ``flips``, every test is wrong with
    that probability (a surface point seen through, a point in the air confirmed), seeded."""

    def __init__(self, surfaces: list[np.ndarray], flips: float = 0.0):
        self.trees = [cKDTree(s) for s in surfaces]
        self.voxel = VOXEL
        self.min_points = 40
        self.flips = flips
        self.rng = np.random.default_rng(0)

    def verdicts(self, points, s):
        on = self.trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        inside = np.all((points > CARCASS[0]) & (points < CARCASS[1]), axis=1)
        through = ~on & ~inside
        if self.flips:
            flip = self.rng.random(len(points)) < self.flips
            on, through = np.where(flip, through, on), np.where(flip, on, through)
        return on.astype(int), through.astype(int)


def _two_drawers():
    """Drawers A (bottom, z 0.05-0.2) and B (right above it, no gap), A pulled over steps 0-8 and
    B over 8-16; a carcass rail under A (static).  Returns the oracle, the true (front A, front B,
    rail) points at step 0 and the strokes."""
    fa, fb = _front(0.05), _front(0.2)
    rail = np.stack(np.meshgrid(np.arange(-0.19, 0.19 + 1e-9, VOXEL), [0.0], [0.02, 0.03, 0.04], indexing="ij"), axis=-1).reshape(-1, 3)
    ya, yb = _stroke(0), _stroke(8)
    surfaces = [np.concatenate([fa - [0, a, 0], fb - [0, b, 0], rail]) for a, b in zip(ya, yb)]
    return surfaces, (fa, fb, rail), (ya, yb)


def test_a_proposal_straddling_two_drawers_gives_the_other_drawers_points_to_its_track():
    surfaces, (fa, fb, _), (ya, yb) = _two_drawers()
    ref = 4  # A half open, B shut: the straddling cluster was seeded where they touched (ref 0 in truth)
    straddle = Proposal("ab", ref, np.concatenate([fa - [0, ya[ref], 0], fb]), _pull(ya, ref))
    b = Proposal("b", 12, fb - [0, yb[12], 0], _pull(yb, 12))
    out = resegment(_Oracle(surfaces), [straddle, b])
    assert [p.name for p in out] == ["ab", "b"]
    # A's proposal keeps exactly A's front; B's receives its own front, carried to its reference
    np.testing.assert_allclose(np.sort(out[0].points, axis=0), np.sort(fa - [0, ya[ref], 0], axis=0), atol=1e-12)
    want_b = np.concatenate([fb, fb]) - [0, yb[12], 0]
    np.testing.assert_allclose(np.sort(out[1].points, axis=0), np.sort(want_b, axis=0), atol=1e-12)
    np.testing.assert_array_equal(out[0].Ts_delta, straddle.Ts_delta)  # motions are kept


def test_a_static_strip_in_a_drawer_proposal_goes_to_the_base():
    surfaces, (fa, _, rail), (ya, _) = _two_drawers()
    a = Proposal("a", 0, np.concatenate([fa, rail]), _pull(ya, 0))
    out = resegment(_Oracle(surfaces), [a])
    np.testing.assert_allclose(np.sort(out[0].points, axis=0), np.sort(fa, axis=0), atol=1e-12)


def test_rigid_proposals_are_not_split_by_noisy_verdicts():
    """Each drawer tracked truly; 2 % of all tests wrong (seven times a 3σ test's rate): nothing
    moves, and the same proposal objects come back."""
    surfaces, (fa, fb, _), (ya, yb) = _two_drawers()
    a = Proposal("a", 4, fa - [0, ya[4], 0], _pull(ya, 4))
    b = Proposal("b", 12, fb - [0, yb[12], 0], _pull(yb, 12))
    out = resegment(_Oracle(surfaces, flips=0.02), [a, b])
    assert len(out) == 2 and out[0] is a and out[1] is b


def test_a_drawer_no_known_motion_explains_leaves_the_proposal():
    """B's front inside A's proposal with B's own proposal absent: A's track puts it in the air in
    front of the carcass while A is out, and the base does so while B is out, so no known motion
    explains it better everywhere: it is dropped (labelled base), and A's front is kept whole."""
    surfaces, (fa, fb, _), (ya, yb) = _two_drawers()
    straddle = Proposal("ab", 0, np.concatenate([fa, fb]), _pull(ya, 0))
    out = resegment(_Oracle(surfaces), [straddle])
    np.testing.assert_allclose(np.sort(out[0].points, axis=0), np.sort(fa, axis=0), atol=1e-12)


def test_a_track_that_fails_at_some_steps_keeps_its_points():
    """A's own track is 6 cm off at two steps of 16 — pulled further out at steps 3 and 5 (every
    point seen through: those steps say nothing about which points are A's) or slid up in its own
    plane at steps 10 and 12 (its top strip in the air there, confirmed at the other steps): no
    point leaves."""
    surfaces, (fa, _, _), (ya, _) = _two_drawers()
    Ts = _pull(ya, 0)
    Ts[[3, 5], 1, 3] -= 0.06
    Ts[[10, 12], 2, 3] += 0.06
    a = Proposal("a", 0, fa, Ts)
    out = resegment(_Oracle(surfaces), [a])
    assert out[0] is a


def test_a_hidden_inside_is_no_evidence_for_a_motion_that_shows_it_elsewhere():
    """A's floor lies deep in the carcass at every step (hidden: its own track gets no verdict);
    B's long pull would carry it out onto a static table in front of the carcass, where the images
    confirm it.  Evidence counts only where the images judge a point as its own track places it,
    so the floor stays with A."""
    fa, fb = _front(0.05), _front(0.2)
    floor = np.stack(np.meshgrid(np.arange(-0.18, 0.18 + 1e-9, VOXEL), np.arange(0.25, 0.39 + 1e-9, VOXEL), [0.05],
                                 indexing="ij"), axis=-1).reshape(-1, 3)
    table = np.stack(np.meshgrid(np.arange(-0.2, 0.2 + 1e-9, VOXEL), np.arange(-0.5, -VOXEL + 1e-9, VOXEL), [0.05],
                                 indexing="ij"), axis=-1).reshape(-1, 3)
    ya, yb = _stroke(0), 0.05 * np.clip(np.arange(STEPS) - 8, 0, 8)  # B out 0.4 m at the end
    surfaces = [np.concatenate([fa - [0, a, 0], fb - [0, b, 0], table]) for a, b in zip(ya, yb)]
    a = Proposal("a", 4, np.concatenate([fa, floor]) - [0, ya[4], 0], _pull(ya, 4))
    b = Proposal("b", 4, fb, _pull(yb, 4))
    oracle = _Oracle(surfaces)
    # the floor carried by B's motion does land on the table, confirmed there
    on_table = [oracle.verdicts(floor - [0, ya[4] + yb[s] - yb[4], 0], s)[0].mean() for s in (14, 15)]
    assert min(on_table) > 0.5
    out = resegment(oracle, [a, b])
    assert out[0] is a and out[1] is b
