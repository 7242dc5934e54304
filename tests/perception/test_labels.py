"""Point labels against the synthetic world's ground-truth label images: the environment (floor,
back wall) takes the environment label at any range, and the static body is one part."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from kinemaforge_opt.perception.change import STATIC, UNKNOWN
from kinemaforge_opt.perception.perceive import static_depth


def test_static_depth_is_the_mean_of_the_static_readings_and_counts_them():
    rng = np.random.default_rng(0)
    T, h, w = 12, 5, 7
    truth = rng.uniform(1.0, 3.0, (h, w))
    D = truth + 0.02 * rng.standard_normal((T, h, w))
    status = np.full((T, h, w), STATIC, dtype=np.int8)
    status[:4, 0, 0] = UNKNOWN  # a pixel static at steps 4.. only
    D[:4, 0, 0] = 0.5  # (what it saw before does not count)
    status[:, 1, 1] = UNKNOWN  # never static
    D[5, 2, 2] = np.nan  # a dropout
    mean, count = static_depth(D.astype(np.float32), status)
    with warnings.catch_warnings():  # the never-static pixel's mean is NaN on purpose
        warnings.simplefilter("ignore", RuntimeWarning)
        want = np.nanmean(np.where(status == STATIC, D, np.nan), axis=0)
    assert np.isnan(mean[1, 1]) and np.isnan(want[1, 1])
    np.testing.assert_allclose(mean[np.isfinite(want)], want[np.isfinite(want)], atol=1e-6)
    assert (count[0, 0], count[1, 1], count[2, 2], count[3, 3]) == (T - 4, 0, T - 1, T)
    # the temporal mean is √T times less noisy than one reading
    err = np.abs(mean - truth)[np.isfinite(want)]
    assert np.sqrt(np.mean(err**2)) < 0.02 / np.sqrt(T) * 1.5


@pytest.fixture(scope="module")
def fridge(tmp_path_factory):
    """A refrigerator (the deepest scene: the back wall ~3 m from the cameras, where one D435
    reading is noisier than the plane band) at 320×240, 2 views, 12 steps."""
    from problems.eval_perception import perceive_instance

    return perceive_instance(tmp_path_factory.mktemp("labels") / "fridge", "refrigerator", 0, views=2, frames=12,
                             width=320, height=240)


def test_environment_pixels_get_the_environment_label(fridge):
    from problems.eval_perception import _confusion

    per, graph, truth = fridge
    counts, _, _ = _confusion(per, graph, truth)
    env = sum(n for (a, b), n in counts.items() if b == "environment")
    body = sum(n for (a, b), n in counts.items() if b == "body")
    assert counts.get(("environment", "environment"), 0) >= 0.97 * env
    assert counts.get(("environment", "body"), 0) <= 0.05 * body
    # the static body is one part: the base holds most of the body's pixels
    assert counts.get(("base", "body"), 0) >= 0.85 * body


def _codes(labels: np.ndarray, names: np.ndarray) -> np.ndarray:
    """Part names -> the int label codes the label helpers work on (names: label_names)."""
    return np.array([list(names).index(n) for n in labels])


def test_a_part_label_spreads_over_the_unsettled_points_it_touches_and_no_further():
    """A drawer's front is labelled by its proposal; the floor it reveals when open (non-static,
    touching the front) joins it; the body's rim beside it (static, 4 mm away) and a non-static
    patch 10 cm off (touching nothing labelled) stay base; where two parts share one connected
    group, each point takes its nearest part."""
    from kinemaforge_opt.perception.reconstruct import BASE, ENVIRONMENT, _spread_part_labels, label_names

    step = 0.005
    grid = np.stack(np.meshgrid(np.arange(0, 0.2, step), np.arange(0, 0.1, step)), -1).reshape(-1, 2)
    front = np.c_[grid[:, 0], np.zeros(len(grid)), grid[:, 1]]  # plane y = 0
    floor = np.c_[grid[:, 0], grid[:, 1] + step, np.zeros(len(grid))]  # plane z = 0 behind it
    rim = np.c_[grid[:, 0], np.full(len(grid), -0.004), grid[:, 1] + 0.102]  # above the front
    far = front[:50] + [0.0, 0.0, 0.3]
    other = np.c_[grid[:, 0] + 0.205, np.zeros(len(grid)), grid[:, 1]]  # a second part beside
    points = np.concatenate([front, floor, rim, far, other])
    n = len(grid)
    labels = np.array([BASE] * len(points), dtype=object)
    labels[:n] = "p0"
    labels[-n:] = "p1"
    labels[3 * n] = ENVIRONMENT  # an environment point is never relabelled
    unsettled = np.ones(len(points), dtype=bool)
    unsettled[2 * n:3 * n] = False  # the rim is static
    names = label_names(["p0", "p1"])
    out = names[_spread_part_labels(points, _codes(labels, names), unsettled, reach=2 * step)]
    assert (out[n:2 * n] == "p0").all()  # the revealed floor (nearer p0's front than p1's)
    assert (out[2 * n:3 * n] == BASE).all()
    assert out[3 * n] == ENVIRONMENT and (out[3 * n + 1:3 * n + 50] == BASE).all()
    assert (out[:n] == "p0").all() and (out[-n:] == "p1").all()
    # nothing labelled, nothing to spread
    assert (names[_spread_part_labels(points, np.zeros(len(points), dtype=int), unsettled, 2 * step)] == BASE).all()


def test_base_points_inside_a_parts_hull_join_it_and_its_neighbours_stay():
    """An open drawer labelled by its front, back and wall tops (a 0.3 × 0.2 × 0.1 m box): its floor and
    inner walls (static to the free-space test, so still BASE) lie inside the hull of those points
    and join it; the cabinet's wall 2 cm beside the drawer, a rim point within one voxel of the
    hull's face, environment points inside it, and anything of a flat second part (no volume)
    are left as they were."""
    from kinemaforge_opt.perception.reconstruct import BASE, ENVIRONMENT, _fill_part_hulls, label_names

    step, voxel = 0.01, 0.005
    xs, ys, zs = np.arange(0, 0.3001, step), np.arange(0, 0.2001, step), np.arange(0, 0.1001, step)
    front = np.array([[x, 0.0, z] for x in xs for z in zs])
    tops = np.array([[x, y, 0.1] for x in (0.0, 0.3) for y in ys] + [[x, 0.2, z] for x in xs for z in zs])
    floor = np.array([[x, y, 0.0] for x in xs[1:-1] for y in ys[1:-1]]) + [0, 0, 0.02]  # raised 2 cm: inside
    inner = np.array([[0.01, y, z] for y in ys[1:-1] for z in zs[2:-2]])  # inner left wall
    cabinet = np.array([[-0.02, y, z] for y in ys for z in zs])  # outside, 2 cm beside the drawer
    rim = np.array([[0.15, 0.1, 0.1 - 0.4 * voxel]])  # inside, nearer the top face than a voxel
    env = np.array([[0.15, 0.1, 0.05]])
    flat = np.array([[x, 0.5, z] for x in xs for z in zs])  # a second, flat part
    points = np.concatenate([front, tops, floor, inner, cabinet, rim, env, flat])
    n = np.cumsum([0, len(front), len(tops), len(floor), len(inner), len(cabinet), 1, 1, len(flat)])
    labels = np.array([BASE] * len(points), dtype=object)
    labels[n[0]:n[2]] = "p0"
    labels[n[6]] = ENVIRONMENT
    labels[n[7]:] = "p1"
    names = label_names(["p0", "p1"])
    out = names[_fill_part_hulls(points, _codes(labels, names), voxel)]
    assert (out[n[2]:n[4]] == "p0").all()  # floor and inner wall joined
    assert (out[n[4]:n[5]] == BASE).all() and out[n[5]] == BASE  # cabinet wall, rim point
    assert out[n[6]] == ENVIRONMENT and (out[n[7]:] == "p1").all() and (out[:n[2]] == "p0").all()


def test_base_speckle_amid_the_floor_becomes_environment_and_the_body_on_it_stays():
    """A 1 × 1 m floor (ENVIRONMENT, 1 cm grid) with five BASE readings 2 cm above it in its
    middle (noise beyond the plane band) and a 0.2 m box standing on it (BASE, its bottom row
    touching the floor): the readings become environment, every point of the box stays base, and
    a part's point amid the floor keeps its part."""
    from kinemaforge_opt.perception.reconstruct import BASE, ENVIRONMENT, _environment_by_majority, label_names

    g = np.arange(0, 1.0001, 0.01)
    floor = np.array([[x, y, 0.0] for x in g for y in g])
    speckle = np.array([[0.2 + 0.1 * i, 0.8, 0.02] for i in range(5)])
    side = np.arange(0, 0.2001, 0.01)
    box = np.array([[0.4 + a, 0.4 + b, 0.0 + c] for a in side for b in side for c in side
                    if min(a, b, c) == 0 or max(a, b, c) > 0.199])  # the box's faces
    box = box[box[:, 2] > 0.005]  # its bottom face rests on the floor, unseen
    part = np.array([[0.8, 0.2, 0.01]])
    points = np.concatenate([floor, speckle, box, part])
    labels = np.array([ENVIRONMENT] * len(floor) + [BASE] * (len(speckle) + len(box)) + ["p0"], dtype=object)
    names = label_names(["p0"])
    out = names[_environment_by_majority(points, _codes(labels, names))]
    n = len(floor)
    assert (out[n:n + 5] == ENVIRONMENT).all()
    assert (out[n + 5:-1] == BASE).all()
    assert out[-1] == "p0" and (out[:n] == ENVIRONMENT).all()


def test_a_parts_mass_does_not_move_with_its_joint_line(fridge):
    """The model rebuilt on other joint lines (as after the NLP) reuses the parts' mass properties:
    each moving part keeps its mass and its centre of mass in the world, and its inertia only turns
    with the link frame — the same as recomputed from scratch on those lines."""
    import dataclasses

    from kinemaforge_opt.perception.reconstruct import build_model, closed_form_lines

    per, graph, _ = fridge
    lines = closed_form_lines(per, graph)
    first = build_model(per, graph, 300.0, lines=lines)
    model0, labels, masses = first[0], first[4], first[5]
    moved = {n: dataclasses.replace(l, origin_world=l.origin_world + np.array([0.05, -0.03, 0.02])) for n, l in lines.items()}
    reused = build_model(per, graph, 300.0, lines=moved, labels=labels, masses=masses)[0]
    fresh = build_model(per, graph, 300.0, lines=moved, labels=labels)[0]
    assert model0.movable_joints
    for j in model0.movable_joints:
        a, b, c = (m.link(j.child).inertial for m in (model0, reused, fresh))
        assert b.mass == pytest.approx(a.mass, rel=1e-9) and c.mass == pytest.approx(a.mass, rel=1e-9)
        np.testing.assert_allclose(b.com, c.com, atol=1e-9)
        np.testing.assert_allclose(b.inertia, c.inertia, atol=1e-9)
        # the link frame moved by the line's offset; the centre of mass stayed where it was
        np.testing.assert_allclose(b.com - a.com, -(moved[j.name].origin_world - lines[j.name].origin_world), atol=1e-9)
