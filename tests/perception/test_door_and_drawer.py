"""A drawer pulled out right above a door that still swings back (protocol_cabinet_multi_0, at
Table 1's size: 8 views × 20 steps at 640×480, D435 noise), perceived from the RGB-D sequence
alone and scored on the generator's ground truth.

At the steps where both move, their moving points are one cluster; a proposal seeded there
followed neither part and took a third of the door's pixels for the drawer (door IoU 0.61, part
IoU 0.69).  Both parts must come out as their own parts, with the right joint types.  And a
drawer pulled out beside a door (protocol_cabinet_multi_1) must come out a slide.  Both failed
from 32835bf and 5ba846a (found by git bisect) until a track whose fit drops is tried from its
reference orientation (Tracker.unturn): the drawers' tracks had turned about their fronts'
normals while they slid (docs/NOTES.md, session after stop 70)."""

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
@pytest.mark.parametrize("name, iou_floor", [
    # the drawer pulled out right above the door as it swings back; door IoU 0.89 and part IoU
    # 0.84 when written, 0.61 and 0.69 when one proposal held door and drawer
    ("protocol_cabinet_multi_0", 0.8),
    # the door pushed open, then the drawer pulled out beside it: right at 22d9c01 (a prismatic
    # drawer, axis 0.04 degrees, part IoU 0.79)
    ("protocol_cabinet_multi_1", 0.7),
])
def test_a_drawer_and_a_door_are_a_slide_and_a_hinge(name, iou_floor, tmp_path):
    s = _scored_at_table1_size(name, tmp_path)
    assert s["topology_ok"] and s["type_accuracy"] == 1.0
    assert s["iou_moving"]["door"] > iou_floor
    assert s["part_iou"] > iou_floor


@pytest.mark.slow
def test_the_points_make_a_helix_on_the_drawer_a_slide(tmp_path):
    """protocol_cabinet_multi_1's drawer given the helix its edge also holds (as the graph chose
    while the drawer's track turned): the closed forms on the observed points (nlp.screw_type)
    make it a slide again (perception.reconstruct.supported_screws), and the reconstruction of
    the sequence has a slide and a hinge."""
    from problems.catalogue import get_case
    from kinemaforge_opt.graph import infer_tree
    from kinemaforge_opt.io.sequence import load_sequence
    from kinemaforge_opt.nlp.reconstruction import ScrewOptions
    from kinemaforge_opt.perception.perceive import perceive
    from kinemaforge_opt.perception.reconstruct import (DEFAULT_DENSITY, build_model, closed_form_lines,
                                                        reconstruct_sequence, supported_screws)
    from kinemaforge_opt.synth import generate_case

    case = dataclasses.replace(get_case("protocol_cabinet_multi_1"), views=8, frames=20, width=640, height=480)
    generate_case(case, tmp_path / "case")
    seq = load_sequence(tmp_path / "case" / "sequence")
    per = perceive(seq)
    graph = infer_tree(per.tracks)
    (k, slide), = [(k, j) for k, j in enumerate(graph.best.joints) if j.type == "prismatic"]
    helix = graph.edges[(slide.parent, slide.child)]["helical"]
    joints = list(graph.best.joints)
    helix = dataclasses.replace(helix, confidence=slide.hypothesis.confidence)
    joints[k] = dataclasses.replace(slide, hypothesis=helix)
    graph = dataclasses.replace(graph, best=dataclasses.replace(graph.best, joints=tuple(joints)))
    lines = closed_form_lines(per, graph)
    built = build_model(per, graph, DEFAULT_DENSITY, "cabinet", lines, gravity=seq.gravity)
    graph, _, _, notes = supported_screws(per, graph, seq, DEFAULT_DENSITY, "cabinet", lines, built,
                                          ScrewOptions().points_per_part)
    assert sorted(j.type for j in graph.best.joints) == ["prismatic", "revolute"]
    (note,) = notes
    assert "a prismatic joint" in note

    rec = reconstruct_sequence(tmp_path / "case" / "sequence")
    assert sorted(j["type"] for j in rec.document["joints"]) == ["prismatic", "revolute"]
