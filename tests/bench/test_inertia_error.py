"""The benchmark's inertia error: what each matched joint moves, against the truth's (Pinocchio's
joint-space inertia; the scaled copy's error is the scale, by construction of a rigid body)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.bench.metrics import JointScore
from kinemaforge_opt.bench.reconstruction import inertia_errors
from kinemaforge_opt.model import Inertial

from ..nlp_reconstruct.worlds import door_model


def _score(true_joint, est_joint, type_correct=True):
    return JointScore(true_joint, "revolute", est_joint, "revolute", 0.0, 0.0, type_correct, "parts")


def test_a_door_twice_as_heavy_is_a_100_percent_error_and_an_unmatched_joint_none():
    true = door_model([0.0, 0.0, 1.0], [0.3, 0.2, 0.1])
    inert = true.link("door").inertial
    heavy = true.with_link("door", inertial=Inertial(2 * inert.mass, inert.com, 2 * inert.inertia))
    renamed = dataclasses.replace(heavy, joints=tuple(dataclasses.replace(j, name="j0") for j in heavy.joints))
    assert inertia_errors(renamed, true, [_score("hinge", "j0")]) == {"hinge": pytest.approx(1.0)}
    assert inertia_errors(renamed, true, [_score("hinge", None)]) == {}
    assert inertia_errors(renamed, true, [_score("hinge", "j0", type_correct=False)]) == {}
    # the inertia about the hinge, not the mass: the parallel-axis term counts
    I_axis = inert.inertia[2, 2] + inert.mass * np.sum(inert.com[:2] ** 2)
    moved = true.with_link("door", inertial=Inertial(inert.mass, inert.com * [0.5, 1, 1], inert.inertia))
    I_moved = inert.inertia[2, 2] + inert.mass * np.sum((inert.com * [0.5, 1, 1])[:2] ** 2)
    assert inertia_errors(moved, true, [_score("hinge", "hinge")])["hinge"] == pytest.approx(I_moved / I_axis - 1)
