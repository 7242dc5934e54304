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


BEFORE_AXES_ORDER = ("since 32835bf (fused points in their pixels' order, not the world axes') this placement's "
                     "tracks split the scene otherwise (the drawer's own track is dropped by without_unions); "
                     "docs/NOTES.md, session after stop 51")
BEFORE_STARTS = ("since 5ba846a (ICP starts a voxel apart) the drawer's track turns 1 -> 9.5 degrees while it "
                 "slides: the constant-velocity guess wins every tie on its flat front and carries the turn on, "
                 "and the graph fits a helix (the reconstruction's points make it a slide again: "
                 "test_the_reconstruction_makes_the_turning_drawer_a_slide); docs/NOTES.md, session after stop 62")


@pytest.mark.slow
@pytest.mark.parametrize("name, iou_floor", [
    # the drawer pulled out right above the door as it swings back; door IoU 0.89 and part IoU
    # 0.84 when written, 0.61 and 0.69 when one proposal held door and drawer
    pytest.param("protocol_cabinet_multi_0", 0.8, marks=pytest.mark.xfail(strict=True, reason=BEFORE_AXES_ORDER)),
    # the door pushed open, then the drawer pulled out beside it: right at 22d9c01 (a prismatic
    # drawer, axis 0.04 degrees, part IoU 0.79)
    pytest.param("protocol_cabinet_multi_1", 0.7, marks=pytest.mark.xfail(strict=True, reason=BEFORE_STARTS)),
])
def test_a_drawer_and_a_door_are_a_slide_and_a_hinge(name, iou_floor, tmp_path):
    s = _scored_at_table1_size(name, tmp_path)
    assert s["topology_ok"] and s["type_accuracy"] == 1.0
    assert s["iou_moving"]["door"] > iou_floor
    assert s["part_iou"] > iou_floor


@pytest.mark.slow
def test_the_reconstruction_makes_the_turning_drawer_a_slide(tmp_path):
    """protocol_cabinet_multi_1's drawer: the graph fits its turning track with a helix; the
    closed forms on the observed points (nlp.screw_type) make it a slide, and the NLP fits that."""
    from problems.catalogue import get_case
    from kinemaforge_opt.perception.reconstruct import reconstruct_sequence
    from kinemaforge_opt.synth import generate_case

    case = dataclasses.replace(get_case("protocol_cabinet_multi_1"), views=8, frames=20, width=640, height=480)
    generate_case(case, tmp_path / "case")
    rec = reconstruct_sequence(tmp_path / "case" / "sequence")
    assert sorted(j["type"] for j in rec.document["joints"]) == ["prismatic", "revolute"]
    (note,) = [n for n in rec.document["nlp"]["notes"] if n.startswith("type:")]
    assert "a prismatic joint" in note
