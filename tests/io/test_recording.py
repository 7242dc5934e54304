"""Bad recordings exit 2 with a message that names the file, column and row at fault."""

from __future__ import annotations

import re

import pytest

from kinemaforge_opt.cli import main as cli_main
from kinemaforge_opt.errors import InputFileError
from kinemaforge_opt.io.recording import Recording, read_recording, write_recording

LAPTOP = "models/laptop/laptop.urdf"

GOOD = "t,q:hinge,tau:hinge\n" + "".join(f"{0.01 * i},{0.001 * i * i},0.1\n" for i in range(50))

BAD = {
    "unknown_joint": ("t,q:elbow\n0,0\n0.1,0.1\n0.2,0.2\n", None, r"joint \(recorded\) 'elbow' does not exist"),
    "non_monotonic": ("t,q:hinge\n0,0\n0.2,0.1\n0.1,0.2\n", "strictly increasing", None),
    "duplicate_time": ("t,q:hinge\n0,0\n0.1,0.1\n0.1,0.2\n", "strictly increasing", None),
    "nan": ("t,q:hinge\n0,0\n0.1,nan\n0.2,0.2\n", r"q:hinge is not finite at row 1 \(t=0\.1 s\)", None),
    "bad_header": ("time,q:hinge\n0,0\n0.1,0\n", r"first column must be 't'", None),
    "bad_column": ("t,x:hinge\n0,0\n0.1,0\n", r"column 1 'x:hinge' is not one of", None),
    "orphan_tau": ("t,q:hinge,tau:door\n0,0,0\n0.1,0,0\n", r"tau:door has no matching q:door", None),
    "too_short": ("t,q:hinge\n0,0\n0.1,0.1\n0.2,0.2\n0.3,0.3\n", None, "too few"),
    "degrees": ("t,q:hinge\n" + "".join(f"{0.01 * i},{1.5 * i}\n" for i in range(50)), None,
                r"q:hinge spans \[0, 73\.5\] but the joint's limits are \[0, 2\.4\] rad: degrees instead of radians\?"),
    "newton_millimetres": ("t,q:hinge,tau:hinge\n" + "".join(f"{0.01 * i},{0.01 * i},{5000.0}\n" for i in range(50)), None,
                           r"tau:hinge reaches 5000, over 100× the joint's effort limit 5"),
    "jump": ("t,q:hinge\n" + "".join(f"{0.1 * i},{0.1 if i < 2 else 3.3}\n" for i in range(12)), None,
             r"q:hinge jumps by \+3\.2 rad between t = 0\.1 and 0\.2 s, more than π in one sample, on a joint limited"),
    "stop_too_soon": ("t,q:hinge\n" + "".join(f"{0.1 * i},{min(1.0 + 0.15 * i, 2.4)}\n" for i in range(30)), None,
                      r"stays clear of the joint stops the model declares at most from 0\.00 to 0\.80 s .* too little motion to fit"),
    "nan_torque": ("t,q:hinge,tau:hinge\n0,0,0\n0.1,0.1,nan\n0.2,0.2,0\n", r"tau:hinge is not finite at row 1", None),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_recordings_exit_2_with_a_named_message(case, tmp_path, capsys):
    text, read_error, cli_error = BAD[case]
    path = tmp_path / f"{case}.csv"
    path.write_text(text)
    if read_error:
        with pytest.raises(InputFileError, match=read_error) as info:
            read_recording(path)
        assert f"{case}.csv" in str(info.value)
    for command in (["diagnose", LAPTOP, str(path), "--no-drift"], ["calibrate", LAPTOP, str(path)]):
        code = cli_main(command + ["-o", str(tmp_path / "out")])
        assert code == 2
        err = capsys.readouterr().err
        assert err.startswith(f"kinemaforge {command[0]}: error:")
        assert case + ".csv" in err or cli_error and re.search(cli_error, err), err
        assert not (tmp_path / "out" / "model.urdf").exists()


def test_round_trip(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text(GOOD)
    rec = read_recording(path)
    write_recording(tmp_path / "again.csv", rec)
    again = read_recording(tmp_path / "again.csv")
    assert again.joint_names == ("hinge",) and (again.q == rec.q).all() and (again.tau == rec.tau).all()
    assert isinstance(rec, Recording) and rec.v is None


def test_a_joint_without_a_tau_column_is_driven_by_nothing(tmp_path):
    """DESIGN.md's recording.csv: tau is optional per joint (a Furuta pendulum's motor drives the
    arm only); v is given for every joint or none."""
    path = tmp_path / "furuta.csv"
    path.write_text("t,q:theta,q:alpha,tau:theta\n" + "".join(f"{0.01 * i},{0.01 * i},{0.02 * i},0.5\n" for i in range(20)))
    rec = read_recording(path)
    assert rec.joint_names == ("theta", "alpha") and (rec.tau[:, 0] == 0.5).all() and (rec.tau[:, 1] == 0).all()
    path.write_text("t,q:theta,q:alpha,v:theta\n0,0,0,0\n0.1,0.1,0.1,1\n")
    with pytest.raises(InputFileError, match=r"v columns missing for joints \['alpha'\]"):
        read_recording(path)


def test_a_span_too_short_for_the_search_grid_is_named_with_its_length(tmp_path, capsys):
    """30 samples at 100 Hz: enough to calibrate, but diagnose keeps the last quarter for
    held-out predictions and searches on ~33-Hz block means, 7 samples.  The message gives the
    span's length and its samples on that grid (it said "recording has 7 samples" of a 30-row CSV)."""
    path = tmp_path / "short.csv"
    path.write_text("t,q:hinge\n" + "".join(f"{0.01 * i},{0.5 + 0.02 * i}\n" for i in range(30)))
    assert cli_main(["diagnose", LAPTOP, str(path), "--no-drift", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert re.search(r"error: the fit span is 0\.2\d s, [0-9] samples on the 3\d-Hz search grid: too few to identify "
                     r"anything \(at least 10\); the last 25% of the span is kept for held-out predictions", err), err
    assert not (tmp_path / "out").exists()


def test_a_held_mask_of_the_wrong_shape_is_named_and_carried_by_selections():
    """``Recording.held`` (a fit span's annotation: joints resting on a stop) must match q; row
    and joint selections keep it, and the lock of an interval needs both its ends held."""
    import numpy as np

    from kinemaforge_opt.errors import DataError

    t, q = np.arange(4.0), np.zeros((4, 2))
    with pytest.raises(DataError, match=r"recording held must have shape \(4, 2\), got \(4, 1\)"):
        Recording(t, ("a", "b"), q, held=np.ones((4, 1), dtype=bool))
    held = np.array([[True, False], [True, False], [False, False], [True, True]])
    rec = Recording(t, ("a", "b"), q, held=held)
    assert rec.locks().tolist() == [[True, False], [False, False], [False, False]]
    assert rec.select(("b", "a")).held.tolist() == held[:, ::-1].tolist()
    assert rec.rows(np.array([True, True, False, False])).held.tolist() == [[True, False], [True, False]]
    assert Recording(t, ("a", "b"), q, held=np.zeros((4, 2), dtype=bool)).held is None  # nothing held
