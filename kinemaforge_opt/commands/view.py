"""``kinemaforge view OUT``: a meshcat scene of an output folder, saved as OUT/scene.html."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputFileError, KinemaforgeError

REPLAY_TAIL_S = 2.0
"""How long past the recording's end the animation shows a stored replay [s]."""

DESCRIPTION = """\
Build a 3-D scene of an output folder and save it as OUT/scene.html, a single HTML file
that opens in a browser without a server (meshcat viewer inlined).

The scene shows OUT/model.urdf (meshes from OUT, else its boxes/cylinders/spheres, or a
sphere at each link's centre of mass), every joint axis as a yellow arrow and its limits as
an orange arc (revolute) or segment (prismatic).  When OUT holds a joint-space recording
(OUT/recording.csv, else the first OUT/*.csv with q:<joint> columns for the model's joints)
the scene animates the recorded motion and, in grey, the Drake replay of it from the same
initial state under the recorded tau (OUT/replay.csv when the folder holds one, as
`kinemaforge reconstruct` writes: the verified replay, shown until 2 s past the recording's end).
Point clouds, if OUT/clouds.npz exists (one (N, 3) array in metres per part, named by part),
are drawn coloured by part.
"""

EPILOG = """\
examples:
  kinemaforge view out/cal                 writes out/cal/scene.html and prints its path
  kinemaforge view out/rec --serve         the same, and live on a meshcat server
  kinemaforge view out/cal --no-replay     recorded motion only (no Drake)
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "view",
        help="meshcat scene of an output folder (OUT/scene.html)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("out", metavar="OUT", help="a folder holding model.urdf (e.g. from calibrate)")
    p.add_argument("--no-replay", action="store_true", help="do not simulate the recording in Drake")
    p.add_argument("--serve", action="store_true",
                   help="also show the scene on a live meshcat server (prints its URL; Ctrl-C ends it)")
    p.set_defaults(func=run)


def _find_recording(out: Path, model):
    """The recording in ``out`` that fits ``model`` (None if there is none)."""
    from ..io.recording import read_recording

    candidates = [out / "recording.csv"] if (out / "recording.csv").is_file() else sorted(out.glob("*.csv"))
    for path in candidates:
        try:
            rec = read_recording(path)
        except KinemaforgeError:
            continue  # not a joint-space recording (e.g. tracks.csv)
        if set(model.joint_names) <= set(rec.joint_names):
            return rec.select(model.joint_names)
    return None


def _replay(out: Path, model, rec):
    """(t (T,) [s] from the recording's start, q (T, n)) of OUT/replay.csv, clipped to 2 s past the
    recording's end, or None when there is no usable replay.csv."""
    from ..io.recording import read_recording

    path = out / "replay.csv"
    if not path.is_file():
        return None
    try:
        replay = read_recording(path).select(model.joint_names)
    except KinemaforgeError:
        return None
    keep = replay.t <= rec.t[-1] + REPLAY_TAIL_S
    if keep.sum() < 2:
        return None
    return replay.t[keep] - rec.t[0], replay.q[keep]


def write_scene(out: str | Path, replay: bool = True, return_scene: bool = False):
    """Build the scene of the output folder ``out`` (see DESCRIPTION) and write OUT/scene.html;
    returns its path (and the :class:`~kinemaforge_opt.viz.Scene` with ``return_scene``)."""
    from ..model import read_urdf
    from ..verify.reconstruction import load_clouds
    from ..viz import build_view

    out = Path(out)
    if not out.is_dir():
        raise InputFileError(f"output folder {str(out)!r} does not exist")
    model = read_urdf(out / "model.urdf")
    rec = _find_recording(out, model)
    recorded = simulated = None
    if rec is not None:
        recorded = (rec.t - rec.t[0], rec.q)
        stored = _replay(out, model, rec)
        if stored is not None and replay:
            simulated = stored
        elif replay:
            from ..verify import simulate_at
            from ..verify.energy import recorded_velocity

            traj = simulate_at(model, rec.q[0], recorded_velocity(rec)[0], rec.t - rec.t[0],
                               rec if rec.tau is not None else None)
            simulated = (traj.t, traj.q)
    scene = build_view(model, mesh_dir=out, recorded=recorded, simulated=simulated, clouds=load_clouds(out))
    path = scene.save(out / "scene.html")
    return (path, scene) if return_scene else path


def run(args) -> int:
    path, scene = write_scene(args.out, replay=not args.no_replay, return_scene=True)
    print(path)
    if args.serve:
        import time

        live = scene.serve()
        print(f"meshcat: {live.url()}  (Ctrl-C to stop)", flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        finally:
            live.window.server_proc.terminate()
    return 0
