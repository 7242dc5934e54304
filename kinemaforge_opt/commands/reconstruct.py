"""``kinemaforge reconstruct``: an RGB-D sequence, pose tracks or real Sturm logs -> kinematic tree ->
reconstruction.json (and, from a sequence, model.urdf, meshes/ and clouds.npz)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from ..errors import InputFileError, KinemaforgeError
from ..io.atomic import write_text_atomic

# The pipeline's modules (open3d, CasADi, Pinocchio, pydrake) load in `run`, not here:
# `kinemaforge --help` and argument errors then answer in a fraction of a second.

HELP = """\
Infer the kinematic tree of an articulated object from an RGB-D sequence or from part pose
tracks and write OUT/reconstruction.json (joints: name, type, parent, child, axis_world,
origin_world, pitch, radius for revolute/helical, confidence); from a sequence also a
simulation-ready OUT/model.urdf, verified in Drake.

INPUT is one of
  a sequence      a kinemaforge.rgbd/1 folder (sequence.json inside): depth -> point clouds ->
                  moving parts -> SE(3) tracks -> tree; also writes OUT/model.urdf,
                  OUT/meshes/<link>.obj (convex hulls, mass from --density) and OUT/clouds.npz,
                  then verifies the model in Drake: the measured joint motion (OUT/recording.csv,
                  q as the images show it under the final joints, OUT/measured_q.csv, at the steps
                  the part tracks OUT/tracks.csv observe, tau from SEQ/wrenches.csv mapped to joint
                  forces) is replayed (OUT/replay.csv, OUT/trajectories.png); drift at 1, 5, 10,
                  20, 50 s and the energy residual go into reconstruction.json["verification"]
  tracks.csv      t,track,x,y,z,qx,qy,qz,qw (full pose) or t,track,x,y,z (position only),
                  world frame, metres, seconds, quaternion order xyzw
  NNN.log         a real Sturm articulation log: 'x y z' per line (a gripper path, no time)
  a folder        every *.log in it, each reconstructed on its own (joints named after the log)

How it works: every pair of tracks is fitted as rigid, prismatic, revolute and helical; BIC turns
the fits into confidences; tracks joined rigidly merge into parts (the part holding the world is
'base'); the tree is the maximum spanning arborescence on log-confidence.  A recording in which
nothing moves is refused (exit 2) rather than given an invented joint.  A track kept rigid with
a part although it moves relative to it (no joint type fits it: a part tracked badly, or a track
spanning two parts) is a warning on stderr and in reconstruction.json["graph_warnings"]: the tree
may miss a joint there.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "reconstruct", help="RGB-D sequence, pose tracks or Sturm logs -> URDF + reconstruction.json",
        description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  kinemaforge reconstruct out/demo/episode/sequence -o out/rec      (after `kinemaforge demo -o out/demo`)\n"
        "  kinemaforge diagnose out/rec --sequence out/demo/episode/sequence -o out/rec_diag\n"
        "  kinemaforge view out/rec\n"
        "  kinemaforge reconstruct SEQ -o out/rec --drift-range                 the drift with link masses ±1 %\n"
        "  kinemaforge reconstruct tracks.csv -o out/rec_tracks\n"
        "  kinemaforge reconstruct ../shared/data/real/articulation/mechanisms_iros_2010/drawer -o out/drawer\n",
    )
    p.add_argument("input", type=Path, help="an RGB-D sequence folder, tracks.csv, a Sturm .log file, or a folder of .log files")
    p.add_argument("-o", "--out", type=Path, required=True, help="output folder (created)")
    p.add_argument("--method", choices=("graph", "greedy"), default="graph",
                   help="'graph' (constraint graph + arborescence, default) or 'greedy' (ablation)")
    p.add_argument("--k-best", type=int, default=3, help="trees to keep (best + alternatives), default 3")
    p.add_argument("--density", type=float, default=None,
                   help="part density for masses from the meshes [kg/m³] (RGB-D input); default "
                        "perception.reconstruct.DEFAULT_DENSITY, 300 (hollow wood-and-board furniture)")
    nlp = p.add_argument_group("joint-inference NLP (RGB-D input; ablation switches of the seed's Table 2)")
    nlp.add_argument("--no-nlp", dest="nlp", action="store_false",
                     help="keep the closed-form joints of the graph (no screw-axis NLP)")
    nlp.add_argument("--no-coarse-to-fine", dest="coarse_to_fine", action="store_false",
                     help="one NLP solve from the closed form (no vis warm-up with refreshed correspondences)")
    nlp.add_argument("--energy", choices=("soft", "hard", "off"), default="soft",
                     help="energy balance as a soft penalty (default), a hard constraint, or off")
    nlp.add_argument("--energy-weight", type=float, default=1.0, help="weight of the soft energy penalty, default 1")
    nlp.add_argument("--free-axes", dest="gravity_aligned", action="store_false",
                     help="keep every axis as fitted: no refit with the axes within 3° of plumb or level made "
                          "so, nor with a level slide within 10° of its parent's face direction made square to "
                          "it (by default each refit is kept when the BIC prefers it; see its note in "
                          "reconstruction.json[\"nlp\"][\"notes\"])")
    ver = p.add_argument_group("Drake verification (RGB-D input)")
    ver.add_argument("--drift-range", action="store_true",
                     help="also replay with each moving link's mass and inertia 1 %% up and down and report the "
                          "drift's range per horizon (two more replays per moving link): a wide range marks a "
                          "knife edge, e.g. a lid pushed just over its balance point")
    p.set_defaults(func=run)


def _joints(result, prefix: str = "") -> list[dict]:
    """The best tree's joints of a :class:`~kinemaforge_opt.graph.tree.GraphResult` as
    reconstruction.json records (names prefixed with ``prefix``)."""
    out = []
    for j in result.best.joints:
        h = j.hypothesis
        d = {
            "name": prefix + j.name, "type": "fixed" if h.type == "rigid" else h.type,
            "parent": j.parent, "child": j.child,
            "axis_world": None if h.axis_world is None else [float(v) for v in h.axis_world],
            "origin_world": None if h.origin_world is None else [float(v) for v in h.origin_world],
            "pitch": h.pitch, "confidence": h.confidence, "residual_rms_m": h.residual_rms,
        }
        if h.radius is not None:
            d["radius"] = h.radius
        if h.type != "rigid":
            d["limits"] = [float(h.q.min()), float(h.q.max())]
        out.append(d)
    return out


def _alternatives(result) -> list[dict]:
    return [
        {"log_score": t.log_score, "joints": [[j.parent, j.child, j.type] for j in t.joints]}
        for t in result.alternatives
    ]


def run(args) -> int:
    from ..graph import infer_tree
    from ..io.tracks import read_sturm_log, read_tracks

    src: Path = args.input
    if not src.exists():
        raise InputFileError(f"input {str(src)!r} does not exist")
    if src.is_dir() and (src / "sequence.json").is_file():
        return _run_sequence(args)
    if src.is_dir():
        logs = sorted(src.glob("*.log"))
        if not logs:
            raise InputFileError(f"folder {str(src)!r} holds no *.log file")
        inputs = [(f"{log.stem}_", read_sturm_log(log)) for log in logs]
    elif src.suffix == ".log":
        inputs = [("", read_sturm_log(src))]
    else:
        inputs = [("", read_tracks(src))]
    doc = {"joints": [], "links": [], "alternatives": {}, "method": args.method, "graph_warnings": []}
    for prefix, tracks in inputs:
        result = infer_tree(tracks, method=args.method, k_best=args.k_best)
        joints = _joints(result, prefix)
        loose = result.best.loose
        if prefix:  # one log = one mechanism: keep parts apart per log
            for j in joints:
                j["parent"], j["child"] = prefix + j["parent"], prefix + j["child"]
            loose = [dataclasses.replace(w, track=prefix + w.track, part=prefix + w.part) for w in loose]
        doc["graph_warnings"] += [w.record() for w in loose]
        doc["joints"] += joints
        doc["links"] += [{"name": prefix + p, "tracks": list(m)} for p, m in result.best.parts.items()]
        doc["alternatives"][prefix.rstrip("_") or "tracks"] = _alternatives(result)
    write_text_atomic(args.out / "reconstruction.json", json.dumps(doc, indent=2))
    for j in doc["joints"]:
        radius = f" radius {j['radius']:.3f} m" if "radius" in j else ""
        print(f"{j['name']}: {j['type']} {j['parent']} -> {j['child']}{radius} (ρ = {j['confidence']:.2f})")
    _warn(doc["graph_warnings"])
    return 0


def _warn(graph_warnings: list[dict]) -> None:
    """The graph's warnings (``LooseTrack.record``) on stderr, one line each."""
    for w in graph_warnings:
        print(f"warning: {w['message']}", file=sys.stderr)


def _run_sequence(args) -> int:
    from ..nlp.reconstruction import ScrewOptions
    from ..perception.reconstruct import DEFAULT_DENSITY, reconstruct_sequence
    from ..verify.reconstruction import verify_reconstruction
    from ..verify.report import energy_text, range_text

    density = DEFAULT_DENSITY if args.density is None else args.density
    rec = reconstruct_sequence(args.input, args.out, method=args.method, k_best=args.k_best, density=density,
                               nlp=args.nlp, coarse_to_fine=args.coarse_to_fine, energy=args.energy,
                               energy_weight=args.energy_weight,
                               nlp_options=ScrewOptions(gravity_aligned=args.gravity_aligned))
    for j in rec.document["joints"]:
        print(f"{j['name']}: {j['type']} {j['parent']} -> {j['child']} axis {[round(a, 3) for a in j['axis_world']]} "
              f"(ρ = {j['confidence']:.2f})")
    for note in (rec.document.get("nlp") or {}).get("notes", []):
        if note.startswith("axes:"):  # the gravity-aligned refit's decision (--free-axes turns it off)
            print(note)
    _warn(rec.document["graph_warnings"])
    print(f"wrote {args.out / 'reconstruction.json'}, model.urdf, meshes/, clouds.npz "
          f"({rec.document['timing_s']['total']:.1f} s)", flush=True)
    if not rec.model.movable_joints:
        print("verification skipped: the model has no movable joint")
        return 0
    try:
        v = verify_reconstruction(args.out, args.input, reconstruction=rec, with_range=args.drift_range)
    except KinemaforgeError as e:  # the reconstruction stands; say why it could not be verified
        doc = dict(rec.document, verification={"error": str(e)})
        write_text_atomic(args.out / "reconstruction.json", json.dumps(doc, indent=2))
        print(f"kinemaforge reconstruct: the Drake verification failed: {e}", file=sys.stderr)
        return 1
    ranges = v.get("drift_range_m", {})
    drift = ", ".join(f"{h} s: {d:.3g}" + ("*" if v["beyond_recording"][h] else "") + range_text(ranges, h)
                      for h, d in v["drift_m"].items())
    print(f"Drake verification ({v['forcing']}): drift [m] {drift}; energy residual {energy_text(v['energy_residual'])} "
          f"({v['timing_s']['total']:.1f} s)")
    print(f"  * past the {v['recording_duration_s']:.1f} s recording: distance to its last pose, held")
    if ranges:
        print("  (a–b): the drift's range with each moving link's mass 1 % up and down; a wide one marks a knife "
              "edge, where the drift measures that 1 %, not the fit")
    if v["contacts"] == [] and v["forcing"].startswith("none"):
        print("  no wrenches.csv: Drake replays the free response from the first state, so wherever something "
              "pushed a part the drift measures that push, not the model (its dynamics are the meshes' "
              "inertia with no damping: without forces nothing fixes them)")
    measured = ", measured_q.csv" if (args.out / "measured_q.csv").is_file() else ""
    print(f"wrote {args.out / 'recording.csv'}, tracks.csv{measured}, trajectories.png; verification in reconstruction.json")
    return 0
