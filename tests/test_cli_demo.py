"""``kinemaforge demo``: argument errors are named; the main job runs end to end (slow)."""

from __future__ import annotations

import json

import pytest

from kinemaforge_opt.cli import main


def test_bad_size_is_named(tmp_path, capsys):
    assert main(["demo", "-o", str(tmp_path), "--size", "big"]) == 2
    assert "--size must be WIDTHxHEIGHT" in capsys.readouterr().err


@pytest.mark.slow
def test_main_demo_end_to_end(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    for f in ("reconstruction/model.urdf", "reconstruction/reconstruction.json", "reconstruction/scene.html",
              "diagnosis/diagnosis.json", "demo.json"):
        assert (out / f).is_file(), f
    assert "Drake verification: drift" in text and str(out / "reconstruction" / "scene.html") in text
    summary = json.loads((out / "demo.json").read_text())
    assert set(summary["verification"]["drift_m"]) == {"1", "5", "10", "20", "50"}
    door = [j for j in summary["joints"] if j["true_joint"] == "door_joint"]
    assert door and door[0]["type"] == "revolute" and door[0]["axis_error_deg"] < 2.0
