"""`kinemaforge verify`: outputs, conservative check, bad input messages and exit status."""

from __future__ import annotations

import json

import pytest
from verify_models import cabinet, oscillator_recording, slider

from kinemaforge_opt.cli import main
from kinemaforge_opt.io.recording import Recording, write_recording
from kinemaforge_opt.model import write_urdf


@pytest.fixture
def files(tmp_path):
    model = slider(2.0, damping=2.0, spring_stiffness=50.0, spring_rest=0.1)
    write_urdf(model, tmp_path / "model.urdf")
    write_recording(tmp_path / "rec.csv", oscillator_recording(2.0, 50.0, 2.0, 0.1, 0.3, duration=15.0, rate=50.0))
    return tmp_path


def test_verify_with_recording_writes_json_and_plot(files, capsys):
    out = files / "out"
    assert main(["verify", str(files / "model.urdf"), str(files / "rec.csv"), "-o", str(out),
                 "--horizons", "1,5,20", "--continuous"]) == 0
    result = json.loads((out / "verification.json").read_text())
    assert set(result["drift_m"]) == {"1", "5", "20"}
    assert max(result["drift_m"].values()) < 1e-3
    assert result["beyond_recording"] == {"1": False, "5": False, "20": True}
    assert result["energy_residual"] < 0.01
    assert (out / "trajectories.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(out / "verification.json") in capsys.readouterr().out
    assert not list(out.glob(".*.tmp"))


def test_drift_range_is_reported_with_the_flag(files, capsys):
    # a damped spring-slider: 1 % more or less mass moves its replay by ~1 % of its motion
    out = files / "out"
    assert main(["verify", str(files / "model.urdf"), str(files / "rec.csv"), "-o", str(out),
                 "--horizons", "1,5", "--continuous", "--drift-range"]) == 0
    result = json.loads((out / "verification.json").read_text())
    assert set(result["drift_range_m"]) == {"1", "5"}
    for least, largest in result["drift_range_m"].values():
        assert 0.0 <= least <= largest < 0.01
    assert "1 s: " in capsys.readouterr().out


def test_verify_without_recording_is_a_conservative_check(tmp_path):
    write_urdf(cabinet(), tmp_path / "cab.urdf")
    assert main(["verify", str(tmp_path / "cab.urdf"), "-o", str(tmp_path / "out"), "--duration", "3"]) == 0
    result = json.loads((tmp_path / "out" / "verification.json").read_text())
    assert result["mode"] == "free_response"
    assert result["q0"] == [0.0, 0.0]  # mid-range of both joints' limits
    assert result["energy_residual"] < 1e-3


def test_missing_model_file_is_named(tmp_path, capsys):
    assert main(["verify", str(tmp_path / "nope.urdf"), "-o", str(tmp_path / "out")]) == 2
    assert "nope.urdf" in capsys.readouterr().err


def test_recording_joint_not_in_model_is_named(files, capsys):
    rec = oscillator_recording(2.0, 50.0, 2.0, 0.1, 0.3, duration=1.0)
    write_recording(files / "bad.csv", Recording(rec.t, ("hinge",), rec.q))
    assert main(["verify", str(files / "model.urdf"), str(files / "bad.csv"), "-o", str(files / "o")]) == 2
    err = capsys.readouterr().err
    assert "'hinge'" in err and "slider" in err
    assert not (files / "o" / "verification.json").exists()


def test_a_part_pressed_into_its_stop_throughout_has_no_energy_books(tmp_path, capsys):
    """Every sample 2 mm into the stop (a compliant stop stores energy there): no stretch of the
    motion is free of it, so the energy residual is null in the JSON and said to be unavailable
    (and why) on the terminal, not a crash."""
    import numpy as np

    from kinemaforge_opt.model import JointLimits

    write_urdf(slider(2.0, limits=JointLimits(0.0, 0.4)), tmp_path / "model.urdf")
    t = np.arange(0.0, 2.0, 0.01)
    write_recording(tmp_path / "rec.csv", Recording(t, ("x",), np.full((t.size, 1), -0.002), tau=np.full((t.size, 1), -1.0)))
    assert main(["verify", str(tmp_path / "model.urdf"), str(tmp_path / "rec.csv"), "-o", str(tmp_path / "out"),
                 "--horizons", "1"]) == 0
    assert json.loads((tmp_path / "out" / "verification.json").read_text())["energy_residual"] is None
    assert "energy residual n/a (no stretch of the motion free of the joints' stops to book)" in capsys.readouterr().out
