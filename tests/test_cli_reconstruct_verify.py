"""``kinemaforge reconstruct SEQ`` ends with the Drake verification; ``view`` then shows the result
(the whole RGB-D flow on a small synthetic door: slow)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from kinemaforge_opt.cli import main
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.viz import decode_static_html


@pytest.mark.slow
def test_reconstruct_verifies_and_view_shows_it(tmp_path, capsys):
    from kinemaforge_opt.synth import generate_case
    from problems.catalogue import get_case

    paths = generate_case(dataclasses.replace(get_case("tiny_door_clean"), frames=10), tmp_path / "case")
    out = tmp_path / "r"
    assert main(["reconstruct", str(paths.sequence), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Drake verification (wrenches.csv): drift [m] 1 s:" in text
    doc = json.loads((out / "reconstruction.json").read_text())
    v = doc["verification"]
    assert set(v["drift_m"]) == {"1", "5", "10", "20", "50"} and v["energy_residual"] >= 0
    assert all(d >= 0 for d in v["drift_m"].values())
    assert v["beyond_recording"]["50"] and not v["beyond_recording"]["1"]
    for f in ("recording.csv", "replay.csv", "tracks.csv", "trajectories.png"):
        assert (out / f).is_file(), f
    assert main(["view", str(out)]) == 0
    cmds = decode_static_html((out / "scene.html").read_text())
    paths_set = {c["path"] for c in cmds if c["type"] == "set_object"}
    model = read_urdf(out / "model.urdf")
    assert {f"/meshcat/clouds/{link}" for link in model.link_names} <= paths_set
    for j in model.movable_joints:
        assert f"/meshcat/recorded/{j.parent}/joint_{j.name}/axis/head" in paths_set
    assert any(c["type"] == "set_animation" for c in cmds)


@pytest.mark.parametrize("flags,aligned", [([], True), (["--free-axes"], False)])
def test_free_axes_switches_the_gravity_aligned_refit_off(tmp_path, monkeypatch, flags, aligned):
    """`--free-axes` reaches the screw NLP's options, and the default density the reconstruction
    (the run stops at the reconstruction)."""
    from kinemaforge_opt.perception import reconstruct as pipeline

    seen = {}

    def stop(*args, **kwargs):
        seen.update(kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "reconstruct_sequence", stop)
    seq = tmp_path / "seq"
    seq.mkdir()
    (seq / "sequence.json").write_text("{}")
    with pytest.raises(KeyboardInterrupt):
        main(["reconstruct", str(seq), "-o", str(tmp_path / "out"), *flags])
    assert seen["nlp_options"].gravity_aligned is aligned
    assert seen["density"] == pipeline.DEFAULT_DENSITY


@pytest.mark.slow
def test_without_recorded_forces_the_drift_is_said_to_measure_the_push(tmp_path, capsys):
    from kinemaforge_opt.synth import generate_case
    from problems.catalogue import get_case

    paths = generate_case(dataclasses.replace(get_case("tiny_door_clean"), frames=10), tmp_path / "case")
    (paths.sequence / "wrenches.csv").unlink()
    assert main(["reconstruct", str(paths.sequence), "-o", str(tmp_path / "r")]) == 0
    text = capsys.readouterr().out
    assert "Drake verification (none (free response))" in text
    assert "the drift measures that push, not the model" in text
    assert "<dynamics" not in (tmp_path / "r" / "model.urdf").read_text()
