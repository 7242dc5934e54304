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
