"""A joint whose part is not seen at a frame is held there at its closed-form value
(``unseen_hold``), softly: what a descendant shows of it is kept.  Truth: a drawer tracked as two
parts on parallel slides, the front (parent) unseen at the first frames, the body behind it
(child) seen throughout, exact points."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.model import ArticulatedModel, Joint, JointDynamics, JointLimits, Link
from kinemaforge_opt.nlp.reconstruction import ScrewData, ScrewOptions, refine_screws, unseen_hold
from kinemaforge_opt.nlp.visual import SurfaceModel
from kinemaforge_opt.spatial import make_transform

from .worlds import box_inertial, box_surface

AXIS = np.array([0.0, -1.0, 0.0])  # both slides pull out along -y
FRONT, BODY = np.array([0.4, 0.02, 0.15]), np.array([0.36, 0.3, 0.12])  # box sizes [m]
FRONT_AT, BODY_AT = np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.16, 0.1])  # centres at q = 0 [m]
TIMES = np.linspace(0.0, 2.0, 9)
UNSEEN = 4  # the front is not seen at the first four frames
PULL = 0.25 * np.sin(0.7 * TIMES)  # the drawer's opening [m]


def _drawer() -> ArticulatedModel:
    """base -> front (slide "front_slide") -> body (slide "body_slide"), both along AXIS."""
    links = (Link("base"), Link("front", box_inertial(1.0, FRONT, FRONT_AT)), Link("body", box_inertial(2.0, BODY, BODY_AT)))
    joints = tuple(Joint(name, "prismatic", parent, child, make_transform(np.eye(3), np.zeros(3)), AXIS, 0.0,
                         JointLimits(-1.0, 1.0), JointDynamics())
                   for name, parent, child in (("front_slide", "base", "front"), ("body_slide", "front", "body")))
    return ArticulatedModel("drawer", links, joints)


def _data() -> ScrewData:
    """Exact points: the front at PULL where seen, the body at PULL everywhere; the closed form
    has the body at rest on the front (0) and the front at PULL where seen, 0 before."""
    rng = np.random.default_rng(0)
    observed, surfaces = {}, {}
    for link, size, centre in (("front", FRONT, FRONT_AT), ("body", BODY, BODY_AT)):
        S, N = box_surface(size, centre, 0.01)
        fine, _ = box_surface(size, centre, 0.01 / 2.3)
        obs = [fine[rng.choice(len(fine), 300, replace=False)] + q * AXIS for q in PULL]
        if link == "front":
            obs = [None] * UNSEEN + obs[UNSEEN:]
        observed[link], surfaces[link] = obs, SurfaceModel(link, S, N)
    q_init = np.column_stack([np.where(np.arange(TIMES.size) < UNSEEN, 0.0, PULL), np.zeros(TIMES.size)])
    return ScrewData(_drawer(), TIMES, q_init, observed, surfaces, delta=0.002, gate=0.2)


def test_the_hold_covers_the_unseen_front_only_and_is_worth_a_point():
    data = _data()
    idx, target, weight = unseen_hold(data, np.arange(TIMES.size), reached=None)
    n = 2
    np.testing.assert_array_equal(idx % n, 0)  # the front's slide
    np.testing.assert_array_equal(idx // n, np.arange(UNSEEN))  # at its unseen frames
    np.testing.assert_array_equal(target, 0.0)
    np.testing.assert_allclose(weight, 1.0 / 0.002**2)  # a slide: one point at the noise level
    # where the dynamics reach a frame, they place it: no hold there
    assert unseen_hold(data, np.arange(TIMES.size), reached=np.ones(TIMES.size, dtype=bool)) is None


def test_the_body_seen_alone_moves_on_its_own_slide_while_the_unseen_front_holds():
    """At the frames where only the body is seen, only the sum of the two slides is observed.  The
    hold gives it to the body's slide: the front stays at its closed-form value (0), the body's
    slide carries the whole pull.  At the frames that see both, the points place both."""
    r = refine_screws(_data(), ScrewOptions(dyn=False))
    q = r.q  # at the frames
    assert q.shape == (TIMES.size, 2)
    np.testing.assert_allclose(q[:, 0] + q[:, 1], PULL, atol=2e-4)  # the body where its points are
    np.testing.assert_allclose(q[:UNSEEN, 0], 0.0, atol=1e-3 * PULL.max())  # the front held
    np.testing.assert_allclose(q[UNSEEN:, 0], PULL[UNSEEN:], atol=2e-4)
    np.testing.assert_allclose(q[UNSEEN:, 1], 0.0, atol=2e-4)
