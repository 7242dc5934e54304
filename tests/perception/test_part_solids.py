"""A moving part's solid over its motion claims its inside, not the static body beside it
(perception.solids).

A drawer (an open-top box 0.4 × 0.3 × 0.1 m, front at x = 0 when shut) slides out 0.3 m along +x
over steps 0–9 and rests open over steps 10–19.  Its labelled points are what a depth camera's
tracked proposal holds: the front, the side walls and the back wall's top edge.  Its interior
floor, seen only while it rests open, is BASE (the free-space test reads it static).  A static strut of the body
stands where the shut drawer's inside would be, seen at every step."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.perception.solids import fill_part_solids, part_motions

VOXEL = 0.01
STEPS = 20
q = np.concatenate([np.linspace(0.0, 0.3, 10), np.full(10, 0.3)])


def _grid(x, y, z) -> np.ndarray:
    return np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1).reshape(-1, 3)


def _scene():
    """(points per step, labels per step, motions, interior-floor masks, strut masks)."""
    front = _grid([0.0], np.arange(-0.15, 0.151, 0.01), np.arange(-0.02, 0.101, 0.01))
    sides = _grid(np.arange(-0.4, 0.0, 0.01), [-0.15, 0.15], np.arange(-0.02, 0.101, 0.01))
    back_top = _grid([-0.4], np.arange(-0.15, 0.151, 0.01), [0.1])
    drawer = np.concatenate([front, sides, back_top])
    floor = _grid(np.arange(0.02, 0.26, 0.01), np.arange(-0.1, 0.101, 0.01), [0.03])  # in the world, open drawer
    strut = _grid(np.arange(-0.3, -0.19, 0.01), [0.0], np.arange(0.03, 0.08, 0.01))  # static, world
    T = np.repeat(np.eye(4)[None], STEPS, axis=0)
    T[:, 0, 3] = q
    points, labels, floor_masks, strut_masks = [], [], [], []
    for s in range(STEPS):
        pieces = [(drawer + [q[s], 0.0, 0.0], "p0", "drawer"), (strut, "base", "strut")]
        if s >= 10:
            pieces.append((floor, "base", "floor"))
        points.append(np.concatenate([p for p, _, _ in pieces]))
        labels.append(np.concatenate([np.full(len(p), lab, object) for p, lab, _ in pieces]))
        what = np.concatenate([np.full(len(p), w) for p, _, w in pieces])
        floor_masks.append(what == "floor")
        strut_masks.append(what == "strut")
    return points, labels, {"p0": T}, floor_masks, strut_masks


def test_the_open_drawer_claims_its_floor_and_leaves_the_static_strut():
    points, labels, motions, floor, strut = _scene()
    out = fill_part_solids(points, labels, motions, VOXEL, "base")
    for s in range(10, STEPS):
        assert (out[s][floor[s]] == "p0").all(), f"step {s}: interior floor not claimed"
    for s in range(STEPS):
        assert (out[s][strut[s]] == "base").all(), f"step {s}: static strut taken by the drawer"
        assert (out[s][labels[s] == "p0"] == "p0").all()


def test_a_step_without_a_motion_is_left_as_labelled():
    points, labels, motions, floor, _ = _scene()
    T = motions["p0"].copy()
    T[15] = np.nan
    out = fill_part_solids(points, labels, {"p0": T}, VOXEL, "base")
    assert (out[15] == labels[15]).all()
    assert (out[14][floor[14]] == "p0").all()


def test_a_motion_of_the_wrong_length_is_refused_by_name():
    points, labels, motions, _, _ = _scene()
    with pytest.raises(ValueError, match=r"motion of part 'p0' has shape \(19, 4, 4\); expected \(20, 4, 4\)"):
        fill_part_solids(points, labels, {"p0": motions["p0"][:-1]}, VOXEL, "base")
    with pytest.raises(ValueError, match="labels has 19 steps, points 20"):
        fill_part_solids(points, labels[:-1], motions, VOXEL, "base")


def test_part_motions_move_a_prismatic_child_along_its_axis():
    from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointLimits, Link

    inertial = Inertial(1.0, np.zeros(3), np.eye(3) * 0.01)
    model = ArticulatedModel("m", (Link("base", inertial), Link("p0", inertial)),
                             (Joint("j", "prismatic", "base", "p0", np.eye(4), np.array([1.0, 0.0, 0.0]), 0.0,
                                    JointLimits(0.0, 0.3)),))
    T = part_motions(model, q[:, None])["p0"]
    np.testing.assert_allclose(T[:, 0, 3], q, atol=1e-12)
    np.testing.assert_allclose(T[:, :3, :3], np.repeat(np.eye(3)[None], STEPS, axis=0), atol=1e-12)
