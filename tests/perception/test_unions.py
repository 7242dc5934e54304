"""A proposal seeded on two touching parts that both move (perception.track.without_unions).

A drawer pulled out right above a door that still swings back touches it: at such a step their
moving points are one cluster.  The proposal seeded there follows neither part, so its track is
lost wherever their motions part (or it follows one and drags the other's points along).  When
the two parts are tracked from seeds of their own, at
no fewer steps, after it, and their moved points cover the union's seed, the union is dropped.
A proposal whose seed they cover only in part, or whose track is longer than theirs, stays, and
so does a part seeded after a union."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from kinemaforge_opt.perception.track import Proposal, without_unions

STEPS, VOXEL = 8, 0.01  # time steps, voxel edge [m]


def _slab(lo, hi) -> np.ndarray:
    """Points on a VOXEL grid filling the box [lo, hi] [m], (N, 3)."""
    axes = [np.arange(a, b + 1e-9, VOXEL) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _proposal(name: str, points: np.ndarray, ref: int, seen: list[int]) -> Proposal:
    """A part at rest, observed at the steps ``seen`` (its motion is the identity there)."""
    Ts = np.full((STEPS, 4, 4), np.nan)
    Ts[seen] = np.eye(4)
    return Proposal(name, ref, points, Ts)


DOOR = _slab((0.0, 0.0, 0.0), (0.5, 0.0, 0.5))
DRAWER = _slab((0.0, -0.2, 0.51), (0.5, 0.0, 0.51))
TRACKER = SimpleNamespace(voxel=VOXEL)
ALL = list(range(STEPS))


@pytest.mark.parametrize("union_seen", [[4, 5, 6, 7], ALL])
def test_a_union_of_two_tracked_parts_is_dropped(union_seen):
    union = np.concatenate([DOOR, DRAWER])
    props = [_proposal("u", union, 6, union_seen), _proposal("door", DOOR, 1, ALL),
             _proposal("drawer", DRAWER, 2, ALL)]
    seeds = {"u": (6, union), "door": (1, DOOR), "drawer": (2, DRAWER)}
    assert [p.name for p in without_unions(TRACKER, props, seeds)] == ["door", "drawer"]


def test_a_proposal_covered_in_part_by_shorter_tracks_or_before_stays():
    union = np.concatenate([DOOR, DRAWER])
    half = [_proposal("u", union, 6, ALL), _proposal("door", DOOR, 1, ALL)]  # the door inside the union
    assert [p.name for p in without_unions(TRACKER, half, {"u": (6, union), "door": (1, DOOR)})] == ["u", "door"]
    shorter = [_proposal("u", union, 6, ALL), _proposal("door", DOOR, 1, [1, 2, 6]), _proposal("drawer", DRAWER, 2, [2, 6])]
    seeds = {"u": (6, union), "door": (1, DOOR), "drawer": (2, DRAWER)}
    assert [p.name for p in without_unions(TRACKER, shorter, seeds)] == ["u", "door", "drawer"]


def test_a_track_joined_into_a_dropped_union_returns_on_its_own():
    """A union seeded on a door and a drawer is joined by a third part's own track (where the
    union's track went on to follow that part); the door's and the drawer's later tracks cover the
    union's seed, so it is dropped — and the joined part returns as a proposal of its own, under a
    new name.  A joined piece the kept proposals cover (a duplicate of the drawer) does not, nor
    one seeded at the union's own step (a leftover of the parts its seed spans)."""
    third = _slab((0.0, -0.2, 1.1), (0.5, 0.0, 1.1))
    union = np.concatenate([DOOR, DRAWER])
    props = [_proposal("p0", union, 6, ALL), _proposal("p1", DOOR, 1, ALL), _proposal("p2", DRAWER, 2, ALL)]
    seeds = {"p0": (6, union), "p1": (1, DOOR), "p2": (2, DRAWER)}
    own = _proposal("p1", third, 0, ALL)  # named when seeded, before the door took the name
    duplicate = _proposal("p2", DRAWER, 3, ALL)
    leftover = _proposal("p1", third + 0.3, 6, ALL)  # seeded with the union, elsewhere
    joined = {"p0": [(own, third), (duplicate, DRAWER), (leftover, leftover.points)]}
    out = without_unions(TRACKER, props, seeds, joined)
    assert [p.name for p in out] == ["p1", "p2", "p3"]
    np.testing.assert_array_equal(out[2].points, third)
    assert out[2].ref == 0
    # without the union dropped, nothing returns
    kept = without_unions(TRACKER, props[:1] + [_proposal("p1", DOOR, 1, [1, 2])], {"p0": (6, union), "p1": (1, DOOR)},
                          joined)
    assert [p.name for p in kept] == ["p0", "p1"]
