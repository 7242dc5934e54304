"""Make one benchmark case: object, MuJoCo ground truth, rendered RGB-D sequence, and the files of
every entry level.

Output layout of ``generate_case(case, OUT)``::

    OUT/sequence/                 kinemaforge.rgbd/1 (sequence.json, rgb/, depth/, wrenches.csv)
    OUT/tracks.csv                true link poses at the rendered times (one track per link)
    OUT/recording.csv             true q, v and the hand's generalised force tau, at record_hz
    OUT/model.urdf, OUT/meshes/   the nominal model (what a user's CAD would say)
    OUT/ground_truth/true_model.urdf   nominal + the effects a URDF can hold (axis, inertia,
                                       damping, Coulomb friction, spring)
    OUT/ground_truth/effects.json      the concealed effects with values, units, params
    OUT/ground_truth/labels/<camera>/<index:06d>.png   per-pixel part labels (8-bit)
    OUT/ground_truth/case.json         the case, the label legend and what is expected

Ground truth never goes inside ``OUT/sequence``.
"""

from __future__ import annotations

import dataclasses
import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..io.recording import Recording, write_recording
from ..io.sequence import (
    CameraInfo,
    Frame,
    Wrenches,
    depth_to_png,
    frame_paths,
    write_png,
    write_sequence_json,
    write_wrenches,
)
from ..io.tracks import PoseTracks, write_tracks
from ..model import write_urdf
from .case import Case
from .effects import MODEL_EFFECTS, true_model, unit_of
from .groundtruth import Episode, axes_world, simulate
from .objects import SynthObject, make_object, write_meshes
from .render import LABEL_ENVIRONMENT, LABEL_FIRST_LINK, SceneRenderer, look_at
from .sensor import noisy_depth, noisy_rgb

DEPTH_SCALE = 1000.0  # PNG value per metre (1 mm steps)


@dataclass(frozen=True)
class CasePaths:
    """Where :func:`generate_case` wrote each artefact."""

    root: Path
    sequence: Path
    tracks: Path
    recording: Path
    model_urdf: Path
    true_urdf: Path
    effects: Path
    labels: Path
    case_json: Path


def camera_poses(obj: SynthObject, case: Case, times: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Per rendered time, the (camera name, T_world_camera) pairs: ``case.views`` static cameras on
    an arc in front of the object (azimuth ±60°, alternating elevation 20°/40°), or one camera
    sweeping the arc over the episode when ``case.moving_camera``.  Returns one list entry per
    camera with its (T, 4, 4) poses."""
    lo, hi = obj.meshes[obj.model.root.name].bounds
    target = (lo + hi) / 2
    size = float(np.linalg.norm(hi - lo))
    vfov = 2 * np.arctan(np.tan(np.radians(case.hfov_deg) / 2) * case.height / case.width)
    r = 1.4 * size / (2 * np.tan(vfov / 2)) + (hi[1] - lo[1])

    def pose(az, el):
        d = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
        return look_at(target + r * d, target)

    if case.moving_camera:
        s = (times - times[0]) / max(times[-1] - times[0], 1e-9)
        return [("cam0", np.array([pose(np.radians(-50 + 100 * x), np.radians(30)) for x in s]))]
    az = np.radians(np.linspace(-60, 60, case.views)) if case.views > 1 else np.zeros(1)
    out = []
    for c in range(case.views):
        T = pose(az[c], np.radians(20 if c % 2 == 0 else 40))
        out.append((f"cam{c}", np.repeat(T[None], len(times), axis=0)))
    return out


def effects_record(obj: SynthObject, case: Case) -> dict:
    """The ground-truth effects document (DESIGN.md effect-table names and meanings)."""
    nominal = axes_world(obj.model)
    true = axes_world(true_model(obj.model, case.effects))
    items = []
    for e in case.effects:
        params = {k: v for k, v in e.params}
        if e.type == "axis_tilt":
            params["axis_world"] = true[e.joint].tolist()
            params["nominal_axis_world"] = nominal[e.joint].tolist()
        items.append({"joint": e.joint, "type": e.type, "value": e.value,
                      "unit": unit_of(e.type, obj.model.joint(e.joint).type), "params": params,
                      "in_true_urdf": e.type in MODEL_EFFECTS})
    return {"case": case.name, "effects": items}


def _tracks(ep: Episode, idx: np.ndarray) -> PoseTracks:
    Ts = ep.Ts_world_link[idx]  # (T, L, 4, 4)
    return PoseTracks(ep.t[idx], ep.link_names, np.swapaxes(Ts[:, :, :3, 3], 0, 1),
                      np.swapaxes(Ts[:, :, :3, :3], 0, 1))


def scene_renderer(obj: SynthObject, episode: Episode) -> SceneRenderer:
    """The renderer of a case: the object's links, the floor, a back wall 30 cm behind the root
    link, and the links that never move in ``episode`` declared fixed (cast once per camera)."""
    Ts = episode.Ts_world_link  # (T, L, 4, 4)
    fixed = {n: Ts[0, j] for j, n in enumerate(episode.link_names) if np.all(Ts[:, j] == Ts[0, j])}
    return SceneRenderer(obj.meshes, obj.colors, obj.model.link_names,
                         wall_y=float(obj.meshes[obj.model.root.name].bounds[1][1]) + 0.3, fixed_links=fixed)


def _write_view(renderer: SceneRenderer, intr: CameraInfo, frame: Frame, Ts_world_link: np.ndarray,
                case: Case, seq: Path, gt: Path) -> None:
    """Render one view with the links at ``Ts_world_link`` (L, 4, 4), apply the sensor model and
    write the frame's RGB and depth PNGs under ``seq`` and its label PNG under ``gt``.  Each frame
    draws its noise from its own stream (seeded by the case seed and frame index), so views can
    be written in parallel and in any order with the same result."""
    rng = np.random.default_rng([case.seed, 7, frame.index])
    view = renderer.render(Ts_world_link, intr, frame.T_world_camera)
    write_png(seq / frame.rgb, noisy_rgb(view.rgb, case.noise, rng))
    write_png(seq / frame.depth, depth_to_png(noisy_depth(view.depth, view.cos_incidence, case.noise, rng), DEPTH_SCALE))
    write_png(gt / "labels" / frame.camera / f"{frame.index:06d}.png", view.labels)


def _write_views(renderer: SceneRenderer, intr: CameraInfo, frames: list[Frame], link_poses: list[np.ndarray],
                 case: Case, seq: Path, gt: Path, workers: int) -> None:
    """:func:`_write_view` for every frame (with its (L, 4, 4) link poses) on ``workers`` threads
    (ray casting, numpy and PNG encoding release the GIL).  The first failure cancels the views
    not yet started and is raised."""
    with ThreadPoolExecutor(max_workers=workers) as pool:
        jobs = [pool.submit(_write_view, renderer, intr, f, Ts, case, seq, gt) for f, Ts in zip(frames, link_poses)]
        try:
            for job in jobs:
                job.result()
        except BaseException:
            for job in jobs:
                job.cancel()
            raise


def generate_case(case: Case, out_dir: str | Path, workers: int | None = None) -> CasePaths:
    """Generate ``case`` into ``out_dir`` (see the module docstring for the layout).  Views are
    rendered and written by ``workers`` threads (default: one per available core)."""
    root = Path(out_dir)
    seq = root / "sequence"
    gt = root / "ground_truth"
    obj = make_object(case.category, case.seed)
    episode = simulate(obj.model, obj.handles, case.effects, case.plan, case.record_hz)

    idx = np.unique(np.round(np.linspace(0, len(episode.t) - 1, case.frames)).astype(int))
    times = episode.t[idx]
    intr = CameraInfo.from_hfov("camera", case.width, case.height, case.hfov_deg)
    cams = camera_poses(obj, case, times)
    renderer = scene_renderer(obj, episode)
    frames: list[Frame] = []
    link_poses = []
    for k, (i, t) in enumerate(zip(idx, times)):
        for name, Ts_world_camera in cams:
            rgb_path, depth_path = frame_paths(name, len(frames))
            frames.append(Frame(len(frames), float(t), name, Ts_world_camera[k], rgb_path, depth_path))
            link_poses.append(episode.Ts_world_link[i])
    _write_views(renderer, intr, frames, link_poses, case, seq, gt, workers or os.cpu_count() or 1)
    cameras = {name: dataclasses.replace(intr, name=name) for name, _ in cams}
    write_sequence_json(seq, cameras, frames, DEPTH_SCALE, obj.model.gravity)
    write_wrenches(seq / "wrenches.csv", Wrenches(episode.t, episode.grip_world, episode.force_world))

    write_meshes(obj, root)
    model_urdf = write_urdf(obj.model, root / "model.urdf")
    true = true_model(obj.model, case.effects)
    true = dataclasses.replace(true, links=tuple(
        dataclasses.replace(l, visuals=tuple(dataclasses.replace(g, filename="../" + g.filename) for g in l.visuals),
                            collisions=tuple(dataclasses.replace(g, filename="../" + g.filename) for g in l.collisions))
        for l in true.links))
    true_urdf = write_urdf(true, gt / "true_model.urdf")
    recording = write_recording(root / "recording.csv",
                                Recording(episode.t, episode.joint_names, episode.q, episode.v, episode.tau))
    tracks = root / "tracks.csv"
    write_tracks(tracks, _tracks(episode, idx))
    effects = gt / "effects.json"
    write_text_atomic(effects, json.dumps(effects_record(obj, case), indent=1))
    legend = {"0": "nothing", str(LABEL_ENVIRONMENT): "environment"}
    legend.update({str(LABEL_FIRST_LINK + i): n for i, n in enumerate(obj.model.link_names)})
    case_json = gt / "case.json"
    write_text_atomic(case_json, json.dumps({
        "name": case.name, "category": case.category, "seed": case.seed, "expected": case.expected,
        "noise": dataclasses.asdict(case.noise), "plan": dataclasses.asdict(case.plan),
        "views": len(cams), "frames": len(idx), "moving_camera": case.moving_camera,
        "record_hz": case.record_hz, "label_legend": legend,
        "handles": {j: {"link": h.link, "p_link": list(h.p_link)} for j, h in obj.handles.items()},
    }, indent=1))
    return CasePaths(root, seq, tracks, recording, model_urdf, true_urdf, effects, gt / "labels", case_json)
