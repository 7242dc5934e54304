"""Perception at a coarse resolution (160×120: a pixel footprint of ~1 cm at the working
distance, a voxel of ~2.3 cm), scored against the synthetic world's ground-truth label images.

At this voxel the floor next to a door's foot is within one growing step of the door, and the
floor slides along itself under the door's rotation; the growing must not spread over it."""

from __future__ import annotations

import pytest


def _small(tmp_path_factory, category: str, instance: int):
    """(perception, graph, truth) of one instance at 160×120, 4 views, 12 steps."""
    from problems.eval_perception import perceive_instance

    return perceive_instance(tmp_path_factory.mktemp("small") / category, category, instance, views=4, frames=12,
                             width=160, height=120)


@pytest.fixture(scope="module")
def microwave(tmp_path_factory):
    return _small(tmp_path_factory, "microwave", 0)


def test_door_does_not_grow_over_the_floor_at_160x120(microwave):
    from problems.eval_perception import _confusion, score

    per, graph, truth = microwave
    result = score(per, graph, truth)
    assert result["predicted"] == [("body", "door", "revolute")]
    # before the environment planes bounded the growing: door IoU 0.12 (the door's part held
    # most of the floor in front of it)
    assert result["iou_moving"]["door"] >= 0.75
    counts, _, _ = _confusion(per, graph, truth)
    door_pixels = sum(n for (a, b), n in counts.items() if a not in ("base", "environment"))
    floor_as_door = sum(n for (a, b), n in counts.items() if a not in ("base", "environment") and b == "environment")
    # (the floor within the inlier distance, 3.5 cm here, of the door's foot still takes its label)
    assert floor_as_door <= 0.2 * door_pixels


@pytest.fixture(scope="module")
def laptop(tmp_path_factory):
    return _small(tmp_path_factory, "laptop", 1)


def test_laptop_base_on_the_floor_is_not_environment_at_160x120(laptop):
    from problems.eval_perception import score

    per, graph, truth = laptop
    result = score(per, graph, truth)
    # the base, ~2 cm thick on the floor, lay within the 3.5 cm inlier distance (1.5 voxels) of
    # the floor plane and was labelled environment whole: base IoU 0.0 before the band followed
    # the depth noise
    assert result["iou_base"] >= 0.8
    assert result["iou_moving"]["lid"] >= 0.8
