"""The back-face test of the visual term (nlp.visual.correspond): a seen surface faces the camera
that saw it, so a pair whose surface point, moved, faces away from the observed point's cameras
is left out.  Checked on exact geometry and on a door whose inner face, missing from the surface
model, comes into view as it opens."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.nlp.reconstruction import ScrewOptions, refine_screws
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


def test_a_pair_whose_surface_faces_away_from_the_camera_is_left_out():
    """A plate's top face (normals +z) against points 2 cm below it: seen from below they are
    the plate's underside, which the model lacks, and are left out; seen from above (or with no
    sightlines, or an unoriented model) they pair as before."""
    top = _plate()
    surface = SurfaceModel("plate", top, np.tile([0.0, 0.0, 1.0], (len(top), 1)), oriented=True)
    below = top[::7] + [0.002, 0.003, -0.02]
    T = np.eye(4)
    from_below = np.tile([0.0, 0.1, -1.0], (len(below), 1)) / np.sqrt(1.01)
    from_above = -from_below
    assert correspond(below, T, surface, 0.05, 64, 0.002, sightlines=from_below).weights.sum() == 0
    assert correspond(below, T, surface, 0.05, 64, 0.002, sightlines=from_above).weights.sum() == len(below)
    assert correspond(below, T, surface, 0.05, 64, 0.002).weights.sum() == len(below)
    unoriented = dataclasses.replace(surface, oriented=False)
    assert correspond(below, T, unoriented, 0.05, 64, 0.002, sightlines=from_below).weights.sum() == len(below)
    # turned half a turn about x, the top face faces down: now the points below are its own
    R = np.eye(4)
    R[:3, :3] = exp_so3(np.array([np.pi, 0.0, 0.0]))
    assert correspond(below @ R[:3, :3].T, R, surface, 0.05, 64, 0.002,
                      sightlines=from_below @ R[:3, :3].T).weights.sum() == 0
    assert correspond(below @ R[:3, :3].T, R, surface, 0.05, 64, 0.002,
                      sightlines=from_above @ R[:3, :3].T).weights.sum() == len(below)


def _hinge_offset(result) -> tuple[float, float]:
    """(axis error [deg], distance [m] of the fitted hinge line from the true one at the origin's
    height) of the single hinge fitted by ``result``."""
    j = result.model.joint("hinge")
    a, o = normalize(j.axis), j.T_parent_joint[:3, 3]
    at_origin = o + a * (ORIGIN[2] - o[2]) / a[2]
    return float(np.degrees(np.arccos(abs(a[2])))), float(np.linalg.norm((at_origin - ORIGIN)[:2]))


def test_the_inner_face_of_an_opened_door_does_not_pull_its_hinge():
    """A 4 cm thick door swinging 80° towards two cameras, 6 mm noise.  The zero-step surface
    model holds what the cameras see of the closed door; once it opens one camera sees its inner
    face, which pairs with the front face a door thickness away.  Without sightlines that pulls
    the hinge towards the cameras (5 mm here, 1° tilt); with them those pairs are left out."""
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    init = door_model(exp_so3(normalize([1.0, 1.0, 0.0]) * np.radians(2.0)) @ np.array([0.0, 0.0, 1.0]),
                      ORIGIN + [0.01, -0.008, 0.0])
    cameras = np.array([[-1.2, 1.5, 0.6], [1.8, 1.5, 0.6]])
    options = ScrewOptions(dyn=False, gravity_aligned=False)
    blind = refine_screws(seen_door_data(true, init, cameras, 0.006, sightlines=False)[0], options)
    seeing = refine_screws(seen_door_data(true, init, cameras, 0.006)[0], options)
    tilt, offset = _hinge_offset(blind)
    assert tilt > 0.5 and offset > 0.004
    tilt, offset = _hinge_offset(seeing)
    assert tilt < 0.2 and offset < 0.002


def test_sightlines_that_do_not_match_the_points_are_refused_by_part():
    true = door_model(np.array([0.0, 0.0, 1.0]), ORIGIN)
    data, _ = seen_door_data(true, true, np.array([[0.0, 1.5, 0.6]]), 0.001)
    short = [s[:-1] for s in data.sightlines["door"]]
    with pytest.raises(DataError, match="part 'door': its sightlines do not match"):
        dataclasses.replace(data, sightlines={"door": short})
    with pytest.raises(DataError, match="part 'door': its sightlines do not match"):
        dataclasses.replace(data, sightlines={})
