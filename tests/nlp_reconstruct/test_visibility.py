"""The far side in the visual term (nlp.visual.correspond): a seen surface faces the camera that
saw it, so an observed point whose surface point, moved, faces away from its cameras lies on a
side the surface model lacks, and pairs with that side modelled as a slab (or is left out).
Checked on exact geometry and on a door whose inner face comes into view as it opens."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.nlp.reconstruction import ScrewOptions, correspondences, far_side_thickness, initial_state, refine_screws
from kinemaforge_opt.nlp.visual import SurfaceModel, correspond, surface_model
from kinemaforge_opt.spatial import exp_so3, normalize

from .worlds import door_model, seen_door_data

ORIGIN = np.array([0.3, 0.2, 0.1])


def _plate(n: int = 20, spacing: float = 0.01) -> np.ndarray:
    u, v = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing, indexing="ij")
    return np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])


def test_surface_normals_face_the_cameras_that_saw_the_points():
    pts = _plate() + np.random.default_rng(0).normal(0, 1e-4, (400, 3))
    up = surface_model(pts, 0.01, "plate", sightlines=np.tile([0.3, 0.0, 1.0], (400, 1)))
    down = surface_model(pts, 0.01, "plate", sightlines=np.tile([0.0, -0.3, -1.0], (400, 1)))
    assert up.oriented and down.oriented and not surface_model(pts, 0.01, "plate").oriented
    assert np.all(up.normals[:, 2] > 0.99) and np.all(down.normals[:, 2] < -0.99)


def test_a_point_on_the_far_side_pairs_with_the_slab_or_is_left_out():
    """A plate's top face (normals +z) against points 2 cm below it.  Seen from below they are
    the plate's underside, which the model lacks: with a thickness of 2 cm they pair with the
    top face moved 2 cm down (residual 0), with none they are left out.  Seen from above (or with
    no sightlines, or an unoriented model) they pair with the top face itself, 2 cm off."""
    top = _plate()
    surface = SurfaceModel("plate", top, np.tile([0.0, 0.0, 1.0], (len(top), 1)), oriented=True)
    below = top[::7] + [0.002, 0.003, -0.02]
    n, T = len(below), np.eye(4)
    from_below = np.tile([0.0, 0.1, -1.0], (n, 1)) / np.sqrt(1.01)
    from_above = -from_below

    slab = correspond(below, T, surface, 0.05, 64, 0.002, sightlines=from_below, thickness=0.02)
    assert slab.weights.sum() == n and slab.far_side[:n].all()
    np.testing.assert_allclose(slab.residuals[:n], 0.0, atol=1e-12)
    assert correspond(below, T, surface, 0.05, 64, 0.002, sightlines=from_below).weights.sum() == 0
    for c in (correspond(below, T, surface, 0.05, 64, 0.002, sightlines=from_above, thickness=0.02),
              correspond(below, T, surface, 0.05, 64, 0.002),
              correspond(below, T, dataclasses.replace(surface, oriented=False), 0.05, 64, 0.002,
                         sightlines=from_below, thickness=0.02)):
        assert c.weights.sum() == n and not c.far_side.any()
        np.testing.assert_allclose(c.residuals[:n], 0.02, atol=1e-12)
    # the plate turned half a turn about x, its top face faces down, towards the camera below
    R = np.eye(4)
    R[:3, :3] = exp_so3(np.array([np.pi, 0.0, 0.0]))
    turned = correspond(below @ R[:3, :3].T, R, surface, 0.05, 64, 0.002, sightlines=from_below, thickness=0.02)
    assert turned.weights.sum() == n and not turned.far_side.any()
    turned_back = correspond(below @ R[:3, :3].T, R, surface, 0.05, 64, 0.002, sightlines=from_above, thickness=0.02)
    assert turned_back.far_side[:n].all()


def test_the_thickness_moments_give_the_far_side_residuals_at_another_thickness():
    """Pairs made with a 2 cm slab: the (14, 14) moments in [z; Δ] give Σ w r² of the pairs at
    2 cm + Δ, and robust_value at 2 cm + Δ is the loss of those residuals (far side moved Δ)."""
    from kinemaforge_opt.nlp.visual import pseudo_huber, robust_value, z_vector

    top = _plate()
    surface = SurfaceModel("plate", top, np.tile([0.0, 0.0, 1.0], (len(top), 1)), oriented=True)
    rng = np.random.default_rng(1)
    below = top[::7] + [0.002, 0.003, -0.023] + rng.normal(0, 0.001, (len(top[::7]), 3))
    above = top[::9] + [0.001, 0.0, 0.001]
    up = np.tile([0.0, 0.1, 1.0], (len(above), 1)) / np.sqrt(1.01)
    down = np.tile([0.0, 0.1, -1.0], (len(below), 1)) / np.sqrt(1.01)
    T = np.eye(4)
    c = correspond(np.vstack([above, below]), T, surface, 0.05, 128, 0.002, sightlines=np.vstack([up, down]),
                   thickness=0.02)
    assert c.thickness == 0.02 and c.far_side.sum() == len(below)
    # the underside lies 2.3 cm below the top face: 3 mm beyond a 2 cm slab, on a 2.3 cm one
    assert np.mean(c.residuals[c.far_side]) == pytest.approx(0.003, abs=5e-4)
    assert np.mean((c.residuals - 0.003 * c.far_side)[c.far_side]) == pytest.approx(0.0, abs=5e-4)
    for dt in (0.0, 0.003, -0.005):
        r = c.residuals - dt * c.far_side
        zt = np.append(z_vector(T), dt)
        assert zt @ c.H_thickness @ zt == pytest.approx(np.sum(c.irls * r**2), rel=1e-9)
        assert robust_value(c, T, 0.002, 0.02 + dt) == pytest.approx(
            np.sum(c.weights * pseudo_huber(r, 0.002)) / 0.002**2, rel=1e-9)
    np.testing.assert_allclose(c.H_thickness[:13, :13], c.H)
    assert correspond(below, T, surface, 0.05, 64, 0.002).H_thickness is None


def test_the_far_side_thickness_of_a_slab_is_its_thickness():
    """A 3 cm plate seen from both sides (top face modelled): the underside's points, 2 mm noise,
    give the plate's thickness; a plate seen from above only gives none."""
    rng = np.random.default_rng(0)
    top = _plate(40)
    surface = SurfaceModel("plate", top, np.tile([0.0, 0.0, 1.0], (len(top), 1)), oriented=True)
    below = top[rng.choice(len(top), 300)] + rng.uniform(0.0, 0.01, (300, 3)) * [1, 1, 0] + [0, 0, -0.03]
    below[:, 2] += rng.normal(0.0, 0.002, 300)
    above = top[rng.choice(len(top), 300)] + [0, 0, 0.001]
    up = np.tile([0.0, 0.0, 1.0], (300, 1))
    blocks = [(np.concatenate([above, below]), np.eye(4), np.concatenate([up, -up]))]
    assert far_side_thickness(surface, blocks, 0.002) == pytest.approx(0.03, abs=5e-4)
    assert far_side_thickness(surface, [(above, np.eye(4), up)], 0.002) == 0.0


def _hinge_offset(result) -> tuple[float, float]:
    """(axis error [deg], distance [m] of the fitted hinge line from the true one at the origin's
    height) of the single hinge fitted by ``result``."""
    j = result.model.joint("hinge")
    a, o = normalize(j.axis), j.T_parent_joint[:3, 3]
    at_origin = o + a * (ORIGIN[2] - o[2]) / a[2]
    return float(np.degrees(np.arccos(abs(a[2])))), float(np.linalg.norm((at_origin - ORIGIN)[:2]))


def test_the_inner_face_of_an_opened_door_is_its_far_side_not_its_front():
    """A 4 cm thick door swinging 80° towards two cameras, 6 mm noise.  The zero-step surface
    model holds what the cameras see of the closed door; once it opens one camera sees its inner
    face.  Paired with the front face a door thickness away (no sightlines), it tilts the hinge
    1° and pulls it 5 mm towards the cameras.  As the far side of a slab the tilt goes (< 0.3°);
    the hinge stays ~4 mm off (the edge faces' points, which no slab models, read shallow: the
    thickness comes out 3.8 cm)."""
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    init = door_model(exp_so3(normalize([1.0, 1.0, 0.0]) * np.radians(2.0)) @ np.array([0.0, 0.0, 1.0]),
                      ORIGIN + [0.01, -0.008, 0.0], body_origin=ORIGIN)
    cameras = np.array([[-1.2, 1.5, 0.6], [1.8, 1.5, 0.6]])
    options = ScrewOptions(dyn=False, gravity_aligned=False)
    blind = refine_screws(seen_door_data(true, init, cameras, 0.006, sightlines=False)[0], options)
    seeing = refine_screws(seen_door_data(true, init, cameras, 0.006)[0], options)
    tilt, offset = _hinge_offset(blind)
    assert tilt > 0.8 and offset > 0.004
    tilt, offset = _hinge_offset(seeing)
    assert tilt < 0.3 and offset < 0.005


@pytest.mark.parametrize("offset", [[-0.008, 0.0, 0.0], [0.0, -0.008, 0.0]])
def test_a_far_side_seen_only_once_the_part_has_turned_is_fitted_with_the_motion(offset):
    """One camera sees the 4 cm door's front while it is shut and only its inner face once it has
    opened, as a laptop's lid shows its top closed and its underside open.  From a closed form
    whose hinge is 8 mm off, the slab thickness held at the median depth of the far-side points
    under the current motion absorbs the offset (the hinge stays 5-7 mm off); fitted with the
    motion, the hinge comes back within 0.5 mm and the thickness within 1 mm of the truth."""
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    init = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN + offset, body_origin=ORIGIN)
    data = seen_door_data(true, init, np.array([[1.8, 1.5, 0.6]]), 0.002)[0]
    held = refine_screws(data, ScrewOptions(dyn=False, gravity_aligned=False, fit_thickness=False))
    fitted = refine_screws(data, ScrewOptions(dyn=False, gravity_aligned=False))
    assert _hinge_offset(held)[1] > 0.004 and held.state.thickness == {}
    assert _hinge_offset(fitted)[1] < 0.0005
    assert fitted.state.thickness["door"] == pytest.approx(0.04, abs=0.001)
    assert any("far-side slab thickness fitted" in n for n in fitted.notes)


def test_sightlines_that_do_not_match_the_points_are_refused_by_part():
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    data, _ = seen_door_data(true, true, np.array([[0.0, 1.5, 0.6]]), 0.001)
    short = [s[:-1] for s in data.sightlines["door"]]
    with pytest.raises(DataError, match="part 'door': its sightlines do not match"):
        dataclasses.replace(data, sightlines={"door": short})
    with pytest.raises(DataError, match="part 'door': its sightlines do not match"):
        dataclasses.replace(data, sightlines={})


def test_a_step_where_the_part_is_not_seen_has_no_sightlines_either():
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    data, _ = seen_door_data(true, true, np.array([[-1.2, 1.5, 0.6], [1.8, 1.5, 0.6]]), 0.001)
    observed, sightlines = list(data.observed["door"]), list(data.sightlines["door"])
    observed[3] = sightlines[3] = None
    data = dataclasses.replace(data, observed={"door": observed}, sightlines={"door": sightlines})
    corr = correspondences(data, initial_state(data), 400)["door"]
    assert corr[3].weights.sum() == 0 and corr[7].far_side.any()
