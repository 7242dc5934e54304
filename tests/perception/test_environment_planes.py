"""Environment planes (perception.segment.environment_planes) against planes known by
construction: a floor and a back wall with depth-like noise behind a box; the result is exact
to the noise and the same on every call."""

import numpy as np

from kinemaforge_opt.perception.segment import environment_planes


def _scene(rng):
    floor = np.c_[rng.uniform(-1.0, 1.0, 4000), rng.uniform(-1.0, 0.8, 4000), rng.normal(0.0, 0.003, 4000)]  # z = 0, up to the wall
    wall = np.c_[rng.uniform(-1.0, 1.0, 3000), 0.8 + rng.normal(0.0, 0.003, 3000), rng.uniform(0.0, 1.0, 3000)]  # y = 0.8
    box = rng.uniform([-0.2, -0.2, 0.0], [0.2, 0.2, 0.4], (1500, 3))
    return np.vstack([floor, wall]), np.vstack([floor, wall, box])


def test_floor_and_wall_are_found_to_the_noise_and_repeat_exactly():
    static, scene = _scene(np.random.default_rng(3))
    planes = environment_planes(static, scene, 0.01)
    normals = sorted((tuple(np.round(p.normal, 2)) for p in planes), key=lambda n: -abs(n[2]))
    assert normals == [(0.0, 0.0, 1.0), (0.0, -1.0, 0.0)]  # pointing to the scene side
    for p in planes:
        true_offset = 0.0 if abs(p.normal[2]) > 0.9 else 0.8
        assert abs(np.degrees(np.arccos(min(1.0, np.abs(p.normal).max())))) < 0.3
        assert abs(abs(p.offset) - true_offset) < 0.002
    for _ in range(3):  # the same planes, bit for bit
        again = environment_planes(static, scene, 0.01)
        assert [(tuple(p.normal), p.offset) for p in again] == [(tuple(p.normal), p.offset) for p in planes]
