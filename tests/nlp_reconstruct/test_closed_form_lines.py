"""The closed-form joint lines read q on the samples the graph fitted, not on the part
representatives' common samples (they differ when the base's own track misses steps)."""

from types import SimpleNamespace

import numpy as np
import pytest

from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.io.tracks import PoseTracks
from kinemaforge_opt.perception.reconstruct import closed_form_lines
from kinemaforge_opt.spatial import make_transform, screw_motion

T = 30
ANGLES = np.linspace(0.0, 1.2, T)
AXIS = np.array([0.0, 0.0, 1.0])


@pytest.mark.parametrize("method", ["graph", "greedy"])
def test_q_on_the_fitted_samples_when_the_base_track_misses_steps(method):
    door = [screw_motion(AXIS, np.array([0.5, 0.2, 0.0]), a) @ make_transform(p=(0.9, 0.2, 0.5)) for a in ANGLES]
    body = [make_transform(p=(0.0, 0.0, 0.4))] * T
    P = np.array([[X[:3, 3] for X in door], [X[:3, 3] for X in body]])
    R = np.array([[X[:3, :3] for X in door], [X[:3, :3] for X in body]])
    P[1, -5:], R[1, -5:] = np.nan, np.nan  # the static proposal leaves the view for 5 steps
    tracks = PoseTracks(np.arange(T) * 0.1, ("door", "body"), P, R)
    graph = infer_tree(tracks, method=method)
    (line,) = closed_form_lines(SimpleNamespace(tracks=tracks), graph).values()
    assert line.type == "revolute" and line.q.shape == (T,)
    seen = np.isfinite(line.q)
    assert seen.sum() >= T - 5
    np.testing.assert_allclose(np.abs(line.q[seen]), ANGLES[seen] - ANGLES[0], atol=1e-6)
