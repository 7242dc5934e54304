from factories import shared_data_dir
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinemaforge_opt.errors import InputFileError
from kinemaforge_opt.io.tracks import PoseTracks, read_sturm_log, read_tracks, write_tracks

STURM = str(shared_data_dir() / "real" / "articulation" / "mechanisms_iros_2010")


def _tracks(full=True):
    rng = np.random.default_rng(0)
    P = rng.normal(size=(2, 4, 3))
    P[1, 2] = np.nan
    R = Rotation.random(8, random_state=1).as_matrix().reshape(2, 4, 3, 3)
    R[1, 2] = np.nan
    return PoseTracks(np.arange(4) * 0.1, ("a", "b"), P, R if full else None)


@pytest.mark.parametrize("full", [True, False])
def test_round_trip(tmp_path, full):
    tr = _tracks(full)
    write_tracks(tmp_path / "tracks.csv", tr)
    back = read_tracks(tmp_path / "tracks.csv")
    assert back.names == tr.names
    np.testing.assert_array_equal(back.times, tr.times)
    np.testing.assert_allclose(back.positions, tr.positions, atol=1e-15)
    if full:
        np.testing.assert_allclose(back.Rs_world_track, tr.Rs_world_track, atol=1e-12)
    else:
        assert back.Rs_world_track is None


@pytest.mark.parametrize(
    "text, needle",
    [
        ("t,track,x,y\n", "header"),
        ("t,track,x,y,z\n0,a,1,2,oops\n", "row 2, field 'z'"),
        ("t,track,x,y,z\n0,a,1,2\n", "row 2: expected 5 fields"),
        ("t,track,x,y,z,qx,qy,qz,qw\n0,a,0,0,0,0,0,0,2\n", "row 2, fields 'qx,qy,qz,qw'"),
        ("t,track,x,y,z\n0,a,0,0,0\n0,a,0,0,0\n", "row 3: track 'a' appears twice"),
        ("", "empty file"),
    ],
)
def test_errors_name_file_row_field(tmp_path, text, needle):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(InputFileError) as e:
        read_tracks(f)
    assert str(f) in str(e.value) and needle in str(e.value)


def test_missing_file_named(tmp_path):
    with pytest.raises(InputFileError, match="nope.csv"):
        read_tracks(tmp_path / "nope.csv")


def test_sturm_log():
    tr = read_sturm_log(f"{STURM}/drawer/001.log")
    assert tr.names == ("drawer_001",) and tr.Rs_world_track is None
    assert tr.positions.shape == (1, 265, 3) and tr.times[1] == 1.0


def test_sturm_log_bad_line(tmp_path):
    f = tmp_path / "x.log"
    f.write_text("0 0 0\n1 2\n")
    with pytest.raises(InputFileError, match="line 2"):
        read_sturm_log(f)
