"""Which link the recorded hand pushes, as the NLP's dynamics term sees it: a handle at a door's
edge, right beside the carcass, moves with the door; the whole push belongs to the door even where
the carcass has points as near to it as the door has (the nearest-point rule gave most rows to
the carcass on protocol_microwave_0)."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.io.sequence import Wrenches
from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, Link
from kinemaforge_opt.perception.reconstruct import pushed_links


def _door() -> ArticulatedModel:
    """A 0.4 m door hinged about world z at the origin, closed along +x."""
    door = Link("door", Inertial(2.0, [0.2, 0.0, 0.15], np.diag([0.02, 0.03, 0.01])))
    return ArticulatedModel("door", (Link("base"), door), (Joint("hinge", "revolute", "base", "door", axis=[0, 0, 1]),))


def _slab(x0, x1, y=0.0) -> np.ndarray:
    x, z = np.meshgrid(np.linspace(x0, x1, 41), np.linspace(0.0, 0.3, 31))
    return np.column_stack([x.ravel(), np.full(x.size, y), z.ravel()])


def test_a_push_at_the_doors_edge_goes_to_the_door_not_the_carcass_beside_it():
    model = _door()
    clouds = {"door": _slab(0.0, 0.4), "base": np.vstack([_slab(0.4, 0.8), _slab(-0.2, 0.8, y=0.05)])}
    times = np.linspace(0.0, 1.0, 11)
    q = (0.8 * times**2)[:, None]  # the door swings open by 0.8 rad
    tw = np.linspace(0.0, 1.0, 61)
    qw = np.interp(tw, times, q[:, 0])
    handle = np.array([0.39, 0.0, 0.15])  # 1 cm from the carcass' edge
    points = np.column_stack([handle[0] * np.cos(qw), handle[0] * np.sin(qw), np.full(tw.size, handle[2])])
    forces = np.column_stack([-np.sin(qw), np.cos(qw), np.zeros(tw.size)]) * 3.0
    forces[tw > 0.8] = 0.0  # the hand lets go
    pushed = pushed_links(model, times, q, Wrenches(tw, points, forces), clouds)
    assert list(pushed[tw <= 0.8]) == ["door"] * int((tw <= 0.8).sum())
    assert list(pushed[tw > 0.8]) == [""] * int((tw > 0.8).sum())


def test_a_push_on_the_carcass_moves_no_joint():
    model = _door()
    clouds = {"door": _slab(0.0, 0.4), "base": _slab(0.4, 0.8)}
    times = np.linspace(0.0, 1.0, 11)
    q = (0.8 * times)[:, None]
    tw = np.linspace(0.0, 1.0, 21)
    points = np.tile([0.5, 0.0, 0.15], (tw.size, 1))  # a still point on the carcass
    forces = np.tile([0.0, 2.0, 0.0], (tw.size, 1))
    pushed = pushed_links(model, times, q, Wrenches(tw, points, forces), clouds)
    assert set(pushed) == {""}
