"""The NLP inside the RGB-D flow on a tiny synthetic case (64×48 px, 2 views, 10 steps): the document
reports every term, the URDF holds the refined joints, and the ablation switches act."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from kinemaforge_opt import read_urdf
from kinemaforge_opt.perception import reconstruct_sequence
from kinemaforge_opt.symbolic import build_dynamics


@pytest.fixture(scope="module")
def tiny_case(tmp_path_factory):
    from kinemaforge_opt.synth import generate_case
    from problems.catalogue import get_case

    root = tmp_path_factory.mktemp("tiny")
    return generate_case(dataclasses.replace(get_case("tiny_door"), frames=10), root / "tiny_door")


def test_nlp_results_reach_the_urdf_and_the_document(tiny_case, tmp_path):
    out = tmp_path / "out"
    rec = reconstruct_sequence(tiny_case.sequence, out, show_progress=False)
    doc = json.loads((out / "reconstruction.json").read_text())
    nlp = doc["nlp"]
    assert nlp["enabled"] and isinstance(nlp["success"], bool) and nlp["iterations"] > 0
    assert set(nlp["terms"]) == {"vis", "dyn", "energy", "inertia_prior"} and nlp["terms"]["vis"] is not None
    assert [s["stage"] for s in nlp["stages"]][-1] in ("full", "full_reweighted", "full_refit", "gravity_aligned",
                                                       "gravity_aligned_continued")
    assert doc["timing_s"]["nlp"] > 0
    # the URDF's joints are the document's joints (world axis and origin at q = 0)
    model = read_urdf(out / "model.urdf")
    poses = build_dynamics(model).poses(np.zeros(model.nq))
    for r in doc["joints"]:
        if r["type"] == "fixed":
            continue
        j = model.joint(r["name"])
        T = poses[model.link_names.index(j.child)]
        np.testing.assert_allclose(T[:3, :3] @ j.axis, r["axis_world"], atol=1e-6)
        if r["type"] != "prismatic":
            np.testing.assert_allclose(T[:3, 3], r["origin_world"], atol=1e-6)
        assert j.limits.lower == pytest.approx(r["limits"][0]) and j.limits.upper == pytest.approx(r["limits"][1])
        if "dynamics" in r:  # identified from the recorded push
            assert j.dynamics.damping == pytest.approx(r["dynamics"]["damping"])
    assert rec.model.nq == model.nq


def test_without_nlp_the_closed_form_is_kept(tiny_case, tmp_path):
    with_nlp = reconstruct_sequence(tiny_case.sequence, None, show_progress=False, energy=False)
    without = reconstruct_sequence(tiny_case.sequence, None, show_progress=False, nlp=False)
    assert without.document["nlp"] == {"enabled": False}
    assert with_nlp.document["nlp"]["options"]["energy"] == "off" and with_nlp.document["nlp"]["terms"]["energy"] is None
    # the NLP started from exactly the closed form that the ablation keeps
    closed = {r["name"]: r for r in with_nlp.document["nlp"]["closed_form"]}
    for r in without.document["joints"]:
        np.testing.assert_allclose(closed[r["name"]]["axis_world"], r["axis_world"], atol=1e-12)
