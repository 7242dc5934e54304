"""Which parent a child hangs from, and drawer fragments whose registration flips, with truth
known by construction: two doors on one hinge line (the base is the parent of both), two parents
whose fits are drawn from one distribution (the shorter chain) or are not (the better one), a
door on a door's edge (a real chain), a drawer fragment whose centroid bows while its
orientation flips by π (prismatic), drawers on parallel rails opened in turn (the body is the
parent of each), and the arborescences checked against every tree of a small graph."""

import dataclasses
import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.graph.fit import JointHypothesis
from kinemaforge_opt.graph.motion import WORLD
from kinemaforge_opt.graph.score import closeness_z
from kinemaforge_opt.graph.tree import _arborescences, _carrier, _graph_trees, _pair_fits
from kinemaforge_opt.io.tracks import PoseTracks
from kinemaforge_opt.spatial import axis_angle_error, make_transform, screw_motion, translation_motion

from .tracks import noisy_track

T = 30
SIGMA_P = 1e-3  # position noise per coordinate [m]
SIGMA_R = np.radians(0.3)  # rotation noise per coordinate [rad]
HINGE = np.array([0.0, 0.0, 1.0])
HINGE_POINT = np.array([0.3, 0.1, 0.0])
RAIL = np.array([0.0, -1.0, 0.05]) / np.linalg.norm([0.0, -1.0, 0.05])


def _noisy(poses, rng):
    return noisy_track(poses, rng, SIGMA_P, SIGMA_R)


def _tracks(tracks: dict) -> PoseTracks:
    return PoseTracks(np.arange(T) / 10.0, tuple(tracks), np.array([p for p, _ in tracks.values()]),
                      np.array([r for _, r in tracks.values()]))


def _arcs(result):
    return {(j.parent, j.child, j.type) for j in result.best.joints}


def _coaxial_doors(rng, noise=True):
    """A fridge: a static body, a freezer door (top) and a fridge door (bottom) on one vertical
    hinge line, opened one after the other.  Relative to the freezer door the fridge door also
    turns about that line: both parents explain it alike."""
    a1 = np.r_[np.linspace(0.0, 1.2, T // 2), np.full(T - T // 2, 1.2)]
    a2 = np.r_[np.zeros(T // 2), np.linspace(0.0, 1.0, T - T // 2)]
    freezer = [screw_motion(HINGE, HINGE_POINT, a) @ make_transform(p=(0.6, 0.1, 1.4)) for a in a1]
    fridge = [screw_motion(HINGE, HINGE_POINT, a) @ make_transform(p=(0.6, 0.1, 0.6)) for a in a2]
    body = [make_transform(p=(0.6, -0.3, 0.9))] * T
    if not noise:
        split = lambda poses: (np.array([X[:3, 3] for X in poses]), np.array([X[:3, :3] for X in poses]))  # noqa: E731
        return _tracks({"body": split(body), "freezer": split(freezer), "fridge": split(fridge)})
    return _tracks({"body": _noisy(body, rng), "freezer": _noisy(freezer, rng), "fridge": _noisy(fridge, rng)})


@pytest.mark.parametrize("seed", [None, 0, 1, 2])
def test_coaxial_doors_both_hang_from_the_base(seed):
    """Two doors on one hinge line: the base is the parent of both (seed None: exact tracks,
    where both parents fit without residual and only the simpler chain can decide)."""
    tracks = _coaxial_doors(np.random.default_rng(seed), noise=seed is not None)
    res = infer_tree(tracks)
    assert _arcs(res) == {("base", "freezer", "revolute"), ("base", "fridge", "revolute")}
    for j in res.best.joints:
        assert np.degrees(axis_angle_error(j.hypothesis.axis_world, HINGE)) < 2.0


@pytest.mark.parametrize("seed", range(3))
def test_coaxial_doors_under_camera_drift_hang_from_the_base(seed):
    """Every track drifts by one smooth 4 mm camera shift: relative to the freezer door the
    drift cancels and the fridge door's hinge fits better than relative to the world.  The
    residuals differ only by a smooth, strongly correlated signal — no significant difference —
    and the chain through the freezer door is no better explanation of a door on the body."""
    tracks = _coaxial_doors(np.random.default_rng(20 + seed))
    drift = 4e-3 * np.sin(np.pi * np.arange(T) / T)[:, None] * np.array([1.0, 0.5, 0.0])
    P = tracks.positions + drift[None]
    res = infer_tree(PoseTracks(tracks.times, tracks.names, P, tracks.Rs_world_track))
    assert _arcs(res) == {("base", "freezer", "revolute"), ("base", "fridge", "revolute")}


def test_door_on_a_door_edge_keeps_its_moving_parent():
    """A folding door: the second leaf hinges on the first leaf's free edge.  Relative to the
    base it follows no single axis; the chain through the first leaf is the only explanation."""
    rng = np.random.default_rng(4)
    a1 = np.linspace(0.0, 0.9, T)
    a2 = np.linspace(0.0, -1.4, T)
    leaf1 = [screw_motion(HINGE, HINGE_POINT, a) for a in a1]
    edge = np.array([0.5, 0.0, 0.0])  # leaf 2's hinge line, in leaf 1's frame
    leaf2 = [X @ screw_motion(HINGE, edge, b) for X, b in zip(leaf1, a2)]
    tracks = _tracks({
        "leaf1": _noisy([X @ make_transform(p=(0.25, 0.0, 0.5)) for X in leaf1], rng),
        "leaf2": _noisy([X @ make_transform(p=(0.75, 0.0, 0.5)) for X in leaf2], rng),
    })
    res = infer_tree(tracks)
    assert _arcs(res) == {("base", "leaf1", "revolute"), ("leaf1", "leaf2", "revolute")}
    (j,) = [j for j in res.best.joints if j.child == "leaf2"]
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, HINGE)) < 2.0


def _edges_fridge(rng, fridge_scale):
    """Hand-built constraint graph: the fridge door fitted from the base with 4 mm residuals and
    from the freezer door with ``fridge_scale`` times those, but a higher ρ from the freezer
    door (the arborescence's choice)."""
    e = lambda scale: _hyp(4e-3 * scale * rng.normal(size=(T, 3)))  # noqa: E731
    conf = lambda h, c: {"revolute": dataclasses.replace(h, confidence=c)}  # noqa: E731
    return {("base", "freezer"): conf(e(0.5), 0.99), ("base", "fridge"): conf(e(1.0), 0.3),
            ("freezer", "fridge"): conf(e(fridge_scale), 0.7), ("fridge", "freezer"): conf(e(3.0), 0.01)}


@pytest.mark.parametrize("seed", range(3))
def test_equally_good_parents_prefer_the_shorter_chain(seed):
    """The fridge door's residuals from the base and from the freezer door are drawn from one
    distribution: the data cannot tell the parents apart, and the chain through the freezer
    door is the longer explanation.  The base is the parent of both (the arborescence alone
    picks the freezer door, whose ρ is higher)."""
    parts = {"base": ("world",), "freezer": ("freezer",), "fridge": ("fridge",)}
    tree = _graph_trees(parts, _edges_fridge(np.random.default_rng(seed), 1.0), 1)[0]
    assert {(j.parent, j.child) for j in tree.joints} == {("base", "freezer"), ("base", "fridge")}


def test_a_clearly_better_moving_parent_is_kept():
    """The fridge door's residuals from the freezer door are a third of those from the base:
    a significant difference, and the arborescence's choice stands."""
    parts = {"base": ("world",), "freezer": ("freezer",), "fridge": ("fridge",)}
    tree = _graph_trees(parts, _edges_fridge(np.random.default_rng(0), 1.0 / 3.0), 1)[0]
    assert {(j.parent, j.child) for j in tree.joints} == {("base", "freezer"), ("freezer", "fridge")}


def _hyp(residuals, n_params=9):
    n = len(residuals)
    return JointHypothesis("revolute", HINGE, np.zeros(3), HINGE, np.zeros(3), 0.0, 0.1, np.zeros(n),
                           float(np.sqrt(np.mean(np.sum(residuals**2, axis=1)))), 0.0, SIGMA_P, 0.0, n_params, n,
                           n, 0.0, times=np.arange(n) * 0.1, position_residuals=residuals)


def test_closeness_z_tells_a_misfit_from_an_equal_fit():
    """Same noise for both fits: |z| stays in the 95 % band on most draws (z is ≈ N(0, 1));
    one fit with twice the noise: z is far outside it, and its sign favours the better fit."""
    rng = np.random.default_rng(5)
    zs = [closeness_z(_hyp(SIGMA_P * rng.normal(size=(200, 3))), _hyp(SIGMA_P * rng.normal(size=(200, 3))))
          for _ in range(40)]
    assert np.mean(np.abs(zs) <= 1.96) > 0.85
    good, bad = _hyp(SIGMA_P * rng.normal(size=(200, 3))), _hyp(2 * SIGMA_P * rng.normal(size=(200, 3)))
    assert closeness_z(good, bad) > 5.0 and closeness_z(bad, good) < -5.0


@pytest.mark.parametrize("seed", range(3))
def test_bowed_drawer_fragment_with_flips_is_prismatic(seed):
    """A drawer fragment sliding 30 cm: the registered part of it changes as the drawer comes
    out, so its centroid bows 2.5 cm off the rail (a circle through it turns by ~38°), and the
    registration is turned by π about the front's normal from mid-stroke on.  The orientation
    never turns (up to the flips): a hinge through the bowed path claims a rotation the track
    does not show.  The joint is prismatic along the rail."""
    rng = np.random.default_rng(10 + seed)
    d = np.linspace(0.0, 0.3, T)
    u = 2.0 * d / d[-1] - 1.0
    bow = 0.025 * (1.0 - u**2) * np.array([1.0, 0.0, 0.0])[:, None]  # ⟂ the rail
    poses = [translation_motion(RAIL, di) @ make_transform(p=np.array([0.2, 0.0, 0.3]) + b) for di, b in zip(d, bow.T)]
    P, R = _noisy(poses, rng)
    flip = np.arange(T) >= T // 2
    R[flip] = R[flip] @ Rotation.from_rotvec(np.pi * RAIL).as_matrix()
    (j,) = infer_tree(_tracks({"fragment": (P, R)})).best.joints
    assert j.type == "prismatic"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, RAIL)) < 3.0


def _drawers_in_turn(rng, noise=True):
    """A chest of three drawers on parallel rails, pulled out 25 cm one after the other and left
    open.  Relative to an open drawer another drawer also slides along the rail: every drawer
    and the body explain every drawer, and without noise all of them exactly."""
    third = T // 3
    body = [make_transform(p=(0.4, 0.2, 0.5))] * T
    tracks = {"body": body}
    for i in range(3):
        stroke = 0.25 * np.clip((np.arange(T) - i * third) / (third - 1), 0.0, 1.0)
        front = make_transform(p=(0.4, 0.0, 0.2 + 0.25 * i))
        tracks[f"drawer_{i}"] = [translation_motion(RAIL, d) @ front for d in stroke]
    split = lambda poses: (np.array([X[:3, 3] for X in poses]), np.array([X[:3, :3] for X in poses]))  # noqa: E731
    return _tracks({k: _noisy(v, rng) if noise else split(v) for k, v in tracks.items()})


@pytest.mark.parametrize("seed", [None, 0, 1, 2])
def test_drawers_opened_in_turn_all_hang_from_the_body(seed):
    """Relative to the body each drawer travels its own 25 cm; relative to another drawer it
    travels that drawer's stroke too (it must counter-move while the other one slides).  The
    drawer it is chained to does not carry it: the body is the parent of all three (seed None:
    exact tracks, where every parent fits without residual)."""
    res = infer_tree(_drawers_in_turn(np.random.default_rng(seed), noise=seed is not None))
    assert _arcs(res) == {("base", f"drawer_{i}", "prismatic") for i in range(3)}
    assert res.best.parts["base"] == ("world", "body")
    assert res.best.loose == ()  # every track is a joint's or rigid within the noise: nothing to warn of


def _brute_force_best(parts, rho) -> float:
    """The largest Σ log ρ over every assignment of one parent per non-root part that forms a
    tree rooted at the base, using arcs with ρ > 0 only."""
    others = [p for p in parts if p != "base"]
    best = -np.inf
    for parents in itertools.product(parts, repeat=len(others)):
        up = dict(zip(others, parents))
        if any(rho.get((a, b), 0.0) <= 0.0 for b, a in up.items()):
            continue

        def reaches_base(p, seen=()):
            return p == "base" or (p not in seen and reaches_base(up[p], seen + (p,)))

        if all(reaches_base(p) for p in others):
            best = max(best, sum(np.log(rho[(a, b)]) for b, a in up.items()))
    return best


@pytest.mark.parametrize("seed", range(20))
def test_best_arborescence_is_the_best_tree(seed):
    """Random constraint graphs on five parts, a third of their arcs impossible (ρ = 0): the
    first arborescence scores what the best of all trees scores (enumerated one by one)."""
    rng = np.random.default_rng(seed)
    parts = {p: (p,) for p in ("base", "a", "b", "c", "d")}
    rho = {(a, b): float(rng.uniform(0.01, 1.0) if rng.uniform() > 1 / 3 else 0.0)
           for a in parts for b in parts if a != b and b != "base"}
    for b in parts:  # every part can hang from the base: a tree exists
        if b != "base":
            rho[("base", b)] = max(rho[("base", b)], 1e-3)
    hyp = _hyp(np.zeros((T, 3)))
    edges = {ab: {"revolute": dataclasses.replace(hyp, confidence=r)} for ab, r in rho.items()}
    (arcs,) = _arborescences(parts, edges, 1)
    assert sum(np.log(rho[ab]) for ab in arcs) == pytest.approx(_brute_force_best(parts, rho), abs=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_drawers_opened_in_turn_under_camera_drift_hang_from_the_body(seed):
    """Every track drifts by one smooth 6 mm camera shift: relative to another drawer the drift
    cancels, and that drawer fits better than the world.  Only the travel tells the body apart."""
    tracks = _drawers_in_turn(np.random.default_rng(30 + seed))
    drift = 6e-3 * np.sin(np.pi * np.arange(T) / T)[:, None] * np.array([1.0, 0.0, 0.5])
    res = infer_tree(PoseTracks(tracks.times, tracks.names, tracks.positions + drift[None], tracks.Rs_world_track))
    assert _arcs(res) == {("base", f"drawer_{i}", "prismatic") for i in range(3)}


def test_tray_sliding_out_of_an_opened_drawer_keeps_the_drawer_as_parent():
    """A drawer pulled out 30 cm, then a tray inside it pulled out 20 cm further along the same
    rail, exact tracks.  Relative to the body the tray slides along that rail too and fits
    without residual, as relative to the drawer; but it travels 50 cm there against 20 cm
    relative to the drawer, which carries it.  (With noise the tray's fit relative to the drawer
    carries both tracks' noise, and the parent posterior takes the body before any chain is
    proposed: the travel rule only settles chains the arborescence proposes.)"""
    half = T // 2
    outer = 0.3 * np.clip(np.arange(T) / (half - 1), 0.0, 1.0)
    inner = 0.2 * np.clip((np.arange(T) - half) / (T - half - 1), 0.0, 1.0)
    drawer = [translation_motion(RAIL, d) @ make_transform(p=(0.4, 0.0, 0.3)) for d in outer]
    tray = [X @ translation_motion(RAIL, d) @ make_transform(p=(0.0, 0.0, 0.05)) for X, d in zip(drawer, inner)]
    body = [make_transform(p=(0.4, 0.2, 0.5))] * T
    split = lambda poses: (np.array([X[:3, 3] for X in poses]), np.array([X[:3, :3] for X in poses]))  # noqa: E731
    tracks = _tracks({"body": split(body), "drawer": split(drawer), "tray": split(tray)})
    assert _arcs(infer_tree(tracks)) == {("base", "drawer", "prismatic"), ("drawer", "tray", "prismatic")}


@pytest.mark.parametrize("seed", range(6))
def test_folding_door_folded_then_swung_keeps_its_moving_parent(seed):
    """A folding door: the second leaf folds 0.85 rad on the first leaf's edge (steps 4–11), then
    the first leaf swings the folded pair 0.57 rad (steps 17–21); tracked with 2 mm / 0.43° noise.
    Seen from the base, the second leaf's positions fit a straight slide about as well as the
    hinge on the first leaf (the closeness test cannot tell them apart), but the slide leaves the
    leaf's turns unexplained: the chain stays."""
    rng = np.random.default_rng(40 + seed)
    ramp = lambda a, b, amount: amount * np.clip((np.arange(T) - a) / (b - a), 0.0, 1.0)  # noqa: E731
    leaf1 = [screw_motion(HINGE, HINGE_POINT, a) for a in ramp(17, 21, 0.57)]
    leaf2 = [X @ screw_motion(HINGE, np.array([0.5, 0.0, 0.0]), -b) for X, b in zip(leaf1, ramp(4, 11, 0.85))]
    noisy = lambda poses: noisy_track(poses, rng, 2e-3, np.radians(0.43))  # noqa: E731
    tracks = _tracks({"leaf1": noisy([X @ make_transform(p=(0.25, 0.0, 0.5)) for X in leaf1]),
                      "leaf2": noisy([X @ make_transform(p=(0.75, 0.0, 0.5)) for X in leaf2])})
    assert _arcs(infer_tree(tracks)) == {("base", "leaf1", "revolute"), ("leaf1", "leaf2", "revolute")}


LOST = 18  # the step from which drawer A's track is lost


def _drawer_lost_when_pulled(rng):
    """Two drawers on parallel rails, tracked with noise.  Drawer B is pulled out 25 cm (steps
    6–12), rests, then coasts back 10 cm (steps 17–29); drawer A rests, is pulled 2 cm at step 17
    and its track is lost from step 18 on.  Only the body sees drawer B's coast."""
    steps = np.arange(T)
    body = [make_transform(p=(0.4, 0.2, 0.5))] * T
    a = [translation_motion(RAIL, 0.02 * (k == LOST - 1)) @ make_transform(p=(0.4, 0.0, 0.45)) for k in steps]
    stroke = 0.25 * np.clip((steps - 6) / 6, 0.0, 1.0) - 0.10 * np.clip((steps - LOST + 1) / (T - LOST), 0.0, 1.0)
    b = [translation_motion(RAIL, d) @ make_transform(p=(0.4, 0.0, 0.2)) for d in stroke]
    tracks = {"body": _noisy(body, rng), "drawer_a": _noisy(a, rng), "drawer_b": _noisy(b, rng)}
    for series in tracks["drawer_a"]:
        series[LOST:] = np.nan
    return _tracks(tracks)


@pytest.mark.parametrize("seed", range(8))
def test_a_drawer_lost_when_pulled_does_not_carry_the_one_coasting_after(seed):
    """Relative to drawer A (18 common samples) drawer B's slide fits as well per sample as
    relative to the body (30 samples), and the parents are compared per sample: the body is
    drawer B's parent.  (Compared by their BIC sums, drawer A won by the 12 samples it lacks on
    3 of these 8 draws.)"""
    res = infer_tree(_drawer_lost_when_pulled(np.random.default_rng(seed)))
    assert ("base", "drawer_b", "prismatic") in _arcs(res)
    assert all(j.parent == "base" for j in res.best.joints)


def test_a_parent_tracked_over_part_of_the_recording_is_judged_by_travel_on_shared_samples():
    """The same drawers: drawer B travels 25 + 10 cm relative to the body but about 25 + 2 cm
    relative to drawer A, only because drawer A is not seen while B coasts back.  On the samples
    all three fits share, the two travels differ by about drawer A's own 2-cm travel, no more:
    the travel does not say drawer A carries B (summed over each fit's own samples it did, and
    the chain stayed whatever the fits said)."""
    edges = _pair_fits(_drawer_lost_when_pulled(np.random.default_rng(0)))
    held = edges[("drawer_a", "drawer_b")]["prismatic"]
    assert _carrier(edges, WORLD, "drawer_a", "drawer_b", held) != "parent"
