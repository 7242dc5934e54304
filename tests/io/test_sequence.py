"""kinemaforge.rgbd/1 loading: decoding to metres, and error messages that name file and field."""

import json

import numpy as np
import pytest

from kinemaforge_opt.errors import InputFileError
from kinemaforge_opt.io.sequence import (
    CameraInfo,
    Frame,
    Wrenches,
    depth_to_png,
    frame_paths,
    load_sequence,
    write_png,
    write_sequence_json,
    write_wrenches,
)

W, H = 8, 6


@pytest.fixture
def seq(tmp_path):
    """A two-camera, two-time sequence written with the module's own writers."""
    cams = {n: CameraInfo(n, W, H, 10.0, 10.0, 3.5, 2.5) for n in ("cam0", "cam1")}
    frames = []
    for t in (0.0, 0.1):
        for name in cams:
            index = len(frames)
            rgb, depth = frame_paths(name, index)
            d = np.full((H, W), 1.234)
            d[0, 0] = np.nan
            write_png(tmp_path / rgb, np.full((H, W, 3), [10, 20, 30], dtype=np.uint8))
            write_png(tmp_path / depth, depth_to_png(d, 1000.0))
            frames.append(Frame(index, t, name, np.eye(4), rgb, depth))
    write_sequence_json(tmp_path, cams, frames, 1000.0)
    return tmp_path


def edit(root, fn):
    path = root / "sequence.json"
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def test_round_trip_and_decoding(seq):
    s = load_sequence(seq)
    assert len(s.frames) == 4 and list(s.times) == [0.0, 0.1]
    assert [f.camera for f in s.frames_at(0.1)] == ["cam0", "cam1"]
    np.testing.assert_array_equal(s.cameras["cam1"].K, [[10, 0, 3.5], [0, 10, 2.5], [0, 0, 1]])
    depth = s.read_depth(s.frames[0])
    assert depth.shape == (H, W) and np.isnan(depth[0, 0])
    np.testing.assert_allclose(depth[1:, 1:], 1.234)
    rgb = s.read_rgb(s.frames[0])
    assert rgb.shape == (H, W, 3) and tuple(rgb[0, 0]) == (10, 20, 30)  # RGB order, not BGR
    assert s.wrenches is None
    assert load_sequence(seq / "sequence.json").root == seq


def test_wrenches_round_trip(seq):
    t = np.array([0.0, 0.05])
    write_wrenches(seq / "wrenches.csv", Wrenches(t, np.ones((2, 3)), np.array([[1.0, 2, 3], [4, 5, 6]])))
    w = load_sequence(seq).wrenches
    np.testing.assert_array_equal(w.forces_world[1], [4, 5, 6])
    np.testing.assert_array_equal(w.t, t)


def test_missing_sequence_json(tmp_path):
    with pytest.raises(InputFileError, match=r"sequence\.json does not exist"):
        load_sequence(tmp_path)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d.update(format="other/1"), r"field 'format' must be 'kinemaforge.rgbd/1'"),
        (lambda d: d.update(depth_scale=0), r"field 'depth_scale' must be a positive number"),
        (lambda d: d.update(gravity=[0, 0]), r"field 'gravity' must be a list of 3 finite numbers"),
        (lambda d: d["cameras"]["cam0"].pop("fx"), r"field 'cameras\.cam0\.fx' is missing"),
        (lambda d: d["cameras"]["cam1"].update(width=-4), r"field 'cameras\.cam1\.width' must be a positive integer"),
        (lambda d: d.update(frames=[]), r"field 'frames' must be a non-empty list"),
        (lambda d: d["frames"][2].update(camera="cam9"), r"field 'frames\[2\]\.camera' names camera 'cam9'"),
        (lambda d: d["frames"][1].pop("t"), r"field 'frames\[1\]\.t' is missing"),
        (lambda d: d["frames"][1].update(index=0), r"field 'frames\[1\]\.index' repeats index 0"),
        (lambda d: d["frames"][3]["T_world_camera"][0].__setitem__(0, 2.0),
         r"field 'frames\[3\]\.T_world_camera' must be a rigid transform"),
        (lambda d: d["frames"][3]["T_world_camera"][1].__setitem__(3, float("nan")),
         r"field 'frames\[3\]\.T_world_camera' must be"),
        (lambda d: d["frames"][3].update(T_world_camera=[[1, 0, 0]]),
         r"field 'frames\[3\]\.T_world_camera' must be a 4×4 list"),
    ],
)
def test_bad_fields_are_named(seq, change, message):
    edit(seq, change)
    with pytest.raises(InputFileError, match=message) as e:
        load_sequence(seq)
    assert str(seq / "sequence.json") in str(e.value)


def test_missing_image_names_the_file_and_field(seq):
    (seq / "depth" / "cam1" / "000003.png").unlink()
    with pytest.raises(InputFileError, match=r"000003\.png: file named by field 'frames\[3\]\.depth' does not exist"):
        load_sequence(seq)


def test_bad_depth_images(seq):
    s = load_sequence(seq)
    write_png(seq / s.frames[1].depth, np.zeros((H, W), dtype=np.uint8))
    with pytest.raises(InputFileError, match=r"000001\.png: frames\[index=1\]\.depth must be a 16-bit"):
        s.read_depth(s.frames[1])
    write_png(seq / s.frames[2].depth, np.zeros((H + 1, W), dtype=np.uint16))
    with pytest.raises(InputFileError, match=r"frames\[index=2\]\.depth is 8×7 px but camera 'cam0' is 8×6"):
        s.read_depth(s.frames[2])
    (seq / s.frames[0].rgb).write_bytes(b"not a png")
    with pytest.raises(InputFileError, match=r"000000\.png: frames\[index=0\]\.rgb is not a readable PNG"):
        s.read_rgb(s.frames[0])


def test_bad_wrenches_name_column_and_row(seq):
    (seq / "wrenches.csv").write_text("t,px,py,pz,fx,fy,fz\n0,0,0,0,1,2,3\n0.1,0,0,0,x,2,3\n")
    with pytest.raises(InputFileError, match=r"wrenches\.csv: column 'fx' row 3 is not a number: 'x'"):
        load_sequence(seq)
    (seq / "wrenches.csv").write_text("t,x,y,z\n")
    with pytest.raises(InputFileError, match=r"wrenches\.csv: header must be t,px,py,pz,fx,fy,fz"):
        load_sequence(seq)


def test_depth_to_png_quantises_and_drops_out_of_range():
    d = depth_to_png(np.array([[0.0012, np.nan, 70.0, 1.0]]), 1000.0)
    assert d.dtype == np.uint16 and d.tolist() == [[1, 0, 0, 1000]]
