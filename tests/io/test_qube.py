"""The Qube reader on the real recordings: joint order, angle convention, errors."""

from __future__ import annotations

import numpy as np
import pytest

from factories import shared_data_dir
from kinemaforge_opt.errors import InputFileError
from kinemaforge_opt.io.qube import read_qube_csv

QUBE = shared_data_dir() / "real" / "qube" / "QQS2_data_diffx0" / "example_csv_fin1.csv"


def test_reads_a_real_recording_with_alpha_from_hanging_down():
    rec = read_qube_csv(QUBE, decimate=4)
    assert rec.joint_names == ("theta", "alpha")
    assert rec.t[0] == 0.0 and rec.dt == pytest.approx(0.016, rel=0.02)
    # the file's alpha is wrapped with 0 upright; ours is continuous and ends hanging at 0
    assert np.abs(np.diff(rec.q[:, 1])).max() < 1.0
    assert abs(rec.q[-1, 1]) < 0.1


def test_missing_column_is_named(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("id,alpha,time\n0,0.1,0.0\n1,0.2,0.004\n")
    with pytest.raises(InputFileError, match=r"bad\.csv: missing column\(s\) \['theta'\]"):
        read_qube_csv(bad)
