"""A drawer pulled out right above a door that still swings back (protocol_cabinet_multi_0, at
Table 1's size: 8 views × 20 steps at 640×480, D435 noise), perceived from the RGB-D sequence
alone and scored on the generator's ground truth.

At the steps where both move, their moving points are one cluster; a proposal seeded there
followed neither part and took a third of the door's pixels for the drawer (door IoU 0.61, part
IoU 0.69).  Both parts must come out as their own parts, with the right joint types.  And a
drawer pulled out beside a door (protocol_cabinet_multi_1) must come out a slide.  Both fail
now, each since the commit its xfail names (found by git bisect)."""

from __future__ import annotations

import dataclasses

import pytest


def _scored_at_table1_size(name: str, tmp_path) -> dict:
    """Perception's score (``problems.eval_perception.score``) of catalogue case ``name`` generated
    at Table 1's size (8 views × 20 steps at 640×480) into ``tmp_path``."""
    from problems.catalogue import get_case
    from problems.eval_perception import ground_truth, run, score
    from kinemaforge_opt.synth import generate_case

    case = dataclasses.replace(get_case(name), views=8, frames=20, width=640, height=480)
    generate_case(case, tmp_path)
    per, graph, _, _ = run(tmp_path / "sequence")
    return score(per, graph, ground_truth(tmp_path))


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "since 32835bf (fused points in their pixels' order, not the world axes') this placement's "
    "tracks split the scene otherwise (the drawer's own track is dropped by without_unions); "
    "docs/NOTES.md, session after stop 51"))
def test_a_drawer_above_a_swinging_door_is_two_parts(tmp_path):
    s = _scored_at_table1_size("protocol_cabinet_multi_0", tmp_path)
    assert s["topology_ok"] and s["type_accuracy"] == 1.0
    assert s["iou_moving"]["door"] > 0.8  # 0.89 when written; 0.61 when one proposal held door and drawer
    assert s["part_iou"] > 0.8  # 0.84 when written; 0.69 then


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "since 5ba846a (ICP starts a voxel apart) the drawer's track turns 1 -> 9.5 degrees while it "
    "slides: the constant-velocity guess wins every tie on its flat front and carries the turn on, "
    "and the graph fits a helix; docs/NOTES.md, session after stop 62"))
def test_a_drawer_slid_out_beside_a_door_stays_a_slide(tmp_path):
    # protocol_cabinet_multi_1 at Table 1's size: the door is pushed open, then the drawer pulled
    # out.  Right at 22d9c01 (a prismatic drawer, axis 0.04 degrees).
    s = _scored_at_table1_size("protocol_cabinet_multi_1", tmp_path)
    assert s["topology_ok"] and s["type_accuracy"] == 1.0
