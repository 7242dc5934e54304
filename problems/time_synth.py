"""Time the generation of one benchmark case and measure its size on disk.

    PYTHONPATH=. .venv/bin/python -m problems.time_synth [CASE] [-o DIR] [--workers N]

CASE defaults to ``timing_episode`` (10 s at 30 Hz, 4 views, 640×480: the issue's figure, goal
≤ 30 s on 2 cores).  Prints the wall and CPU time of ``generate_case`` (CPU/wall shows how much
of the machine the run got), the size of each output folder, and a per-view breakdown of the
stages measured one view at a time on a sample of the case's views.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from kinemaforge_opt.io.sequence import depth_to_png, load_sequence, write_png
from kinemaforge_opt.synth.generate import DEPTH_SCALE, generate_case, scene_renderer
from kinemaforge_opt.synth.groundtruth import simulate
from kinemaforge_opt.synth.objects import make_object
from kinemaforge_opt.synth.sensor import noisy_depth, noisy_rgb
from problems.catalogue import get_case


def folder_mb(path: Path) -> float:
    """Total size of the files under ``path`` [MB]."""
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) / 1e6


def stage_breakdown(case, out: Path, sample: int) -> dict[str, float]:
    """Mean single-thread time per view [ms] of each stage, over ``sample`` views spread over the
    sequence generated in ``out`` (same renderer, cameras and link poses as ``generate_case``)."""
    obj = make_object(case.category, case.seed)
    episode = simulate(obj.model, obj.handles, case.effects, case.plan, case.record_hz)
    seq = load_sequence(out / "sequence")
    renderer = scene_renderer(obj, episode)
    times = {"render (ray cast + shading)": 0.0, "sensor model (RGB + depth)": 0.0, "PNG encode + write (3 images)": 0.0}
    rng = np.random.default_rng(0)
    picks = np.unique(np.linspace(0, len(seq.frames) - 1, sample).round().astype(int))
    jobs = []
    for f in (seq.frames[i] for i in picks):
        cam = seq.cameras[f.camera]
        jobs.append((f, cam, episode.Ts_world_link[int(np.argmin(np.abs(episode.t - f.t)))]))
    for f, intr, Ts in jobs:  # the static scene is cast once per camera: not part of the per-view cost
        renderer.render(Ts, intr, f.T_world_camera)
    with tempfile.TemporaryDirectory() as tmp:
        for f, intr, Ts in jobs:
            t0 = time.perf_counter()
            view = renderer.render(Ts, intr, f.T_world_camera)
            t1 = time.perf_counter()
            rgb = noisy_rgb(view.rgb, case.noise, rng)
            depth = depth_to_png(noisy_depth(view.depth, view.cos_incidence, case.noise, rng), DEPTH_SCALE)
            t2 = time.perf_counter()
            for name, img in (("rgb", rgb), ("depth", depth), ("labels", view.labels)):
                write_png(Path(tmp) / f"{name}.png", img)
            t3 = time.perf_counter()
            for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
                times[key] += dt * 1e3 / len(jobs)
    return times


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", nargs="?", default="timing_episode")
    ap.add_argument("-o", "--out", help="output folder (default: a temporary folder, removed afterwards)")
    ap.add_argument("--workers", type=int, help="threads of generate_case (default: one per core)")
    ap.add_argument("--sample", type=int, default=60, help="views timed one at a time for the breakdown")
    args = ap.parse_args(argv)
    case = get_case(args.case)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp)
        wall0, cpu0 = time.perf_counter(), time.process_time()
        generate_case(case, out, workers=args.workers)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        n_views = len(load_sequence(out / "sequence").frames)
        print(f"{case.name}: {n_views} views of {case.width}×{case.height} in {wall:.1f} s wall, "
              f"{cpu:.1f} s CPU (CPU/wall {cpu / wall:.2f})")
        for sub in ("sequence/rgb", "sequence/depth", "ground_truth/labels", "."):
            print(f"  {sub:22s} {folder_mb(out / sub):8.1f} MB")
        print(f"per view, one thread, over {args.sample} views:")
        breakdown = stage_breakdown(case, out, args.sample)
        for stage, ms in breakdown.items():
            print(f"  {stage:32s} {ms:6.1f} ms  (× {n_views} views = {ms * n_views / 1e3:5.1f} s)")
        print(f"  {'total':32s} {sum(breakdown.values()):6.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
