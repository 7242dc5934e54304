"""RGB-D sequence directories (``kinemaforge.rgbd/1``): load, validate, write.

Layout (DESIGN.md)::

    SEQ/sequence.json
    SEQ/rgb/<camera>/<index:06d>.png     8-bit RGB
    SEQ/depth/<camera>/<index:06d>.png   16-bit z-depth, metres × depth_scale, 0 = no reading
    SEQ/wrenches.csv                     optional: t,px,py,pz,fx,fy,fz (N at world point p [m])

Loading checks the JSON fields and that every referenced image exists; images are decoded on
demand (:meth:`Sequence.read_depth`, :meth:`Sequence.read_rgb`), which checks their type and size.
Every error is an :class:`InputFileError` naming the file and the field.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputFileError
from .atomic import atomic_path, write_numeric_csv_atomic, write_text_atomic

FORMAT = "kinemaforge.rgbd/1"
WRENCH_COLUMNS = ("t", "px", "py", "pz", "fx", "fy", "fz")


@dataclass(frozen=True)
class CameraInfo:
    """Pinhole intrinsics of one camera: image size [px], focal lengths and principal point [px]."""

    name: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @staticmethod
    def from_hfov(name: str, width: int, height: int, hfov_deg: float) -> "CameraInfo":
        """Square pixels, principal point at the image centre, horizontal field of view [deg]."""
        f = (width / 2) / np.tan(np.radians(hfov_deg) / 2)
        return CameraInfo(name, width, height, f, f, (width - 1) / 2, (height - 1) / 2)


@dataclass(frozen=True, eq=False)
class Frame:
    """One image pair.  index: unique frame number.  t: time [s] (cameras may share one t).
    T_world_camera: (4, 4) camera pose (OpenCV axes).  rgb, depth: paths relative to the sequence
    root, as written in sequence.json."""

    index: int
    t: float
    camera: str
    T_world_camera: np.ndarray
    rgb: str
    depth: str


@dataclass(frozen=True, eq=False)
class Wrenches:
    """Applied forces: t (N,) [s], points_world (N, 3) [m], forces_world (N, 3) [N]."""

    t: np.ndarray
    points_world: np.ndarray
    forces_world: np.ndarray


@dataclass(frozen=True, eq=False)
class Sequence:
    """A loaded sequence.  root: the SEQ folder.  gravity: (3,) world gravity [m/s²].
    depth_scale: PNG value per metre.  cameras: name -> :class:`CameraInfo`.  frames: in file
    order.  wrenches: the optional applied forces."""

    root: Path
    gravity: np.ndarray
    depth_scale: float
    cameras: dict[str, CameraInfo]
    frames: tuple[Frame, ...]
    wrenches: Wrenches | None = None

    @property
    def times(self) -> np.ndarray:
        """(T,) the distinct frame times [s], sorted."""
        return np.unique([f.t for f in self.frames])

    def frames_at(self, t: float) -> tuple[Frame, ...]:
        """The frames (one per camera view) taken at time ``t`` [s]."""
        return tuple(f for f in self.frames if f.t == t)

    def read_depth(self, frame: Frame) -> np.ndarray:
        """(H, W) z-depth [m] of ``frame``; NaN where the sensor had no reading (PNG value 0)."""
        raw = _read_png(self.root / frame.depth, f"frames[index={frame.index}].depth", cv2.IMREAD_UNCHANGED)
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise InputFileError(
                f"{self.root / frame.depth}: frames[index={frame.index}].depth must be a 16-bit single-channel PNG, "
                f"got dtype {raw.dtype} with shape {raw.shape}"
            )
        self._check_size(raw, frame, "depth")
        depth = raw.astype(float) / self.depth_scale
        depth[raw == 0] = np.nan
        return depth

    def read_rgb(self, frame: Frame) -> np.ndarray:
        """(H, W, 3) uint8 RGB image of ``frame``."""
        bgr = _read_png(self.root / frame.rgb, f"frames[index={frame.index}].rgb", cv2.IMREAD_COLOR)
        self._check_size(bgr, frame, "rgb")
        return bgr[..., ::-1].copy()

    def _check_size(self, image: np.ndarray, frame: Frame, field: str) -> None:
        cam = self.cameras[frame.camera]
        if image.shape[:2] != (cam.height, cam.width):
            raise InputFileError(
                f"{self.root / getattr(frame, field)}: frames[index={frame.index}].{field} is "
                f"{image.shape[1]}×{image.shape[0]} px but camera {frame.camera!r} is {cam.width}×{cam.height}"
            )


def _read_png(path: Path, field: str, flags: int) -> np.ndarray:
    if not path.is_file():
        raise InputFileError(f"{path}: {field} file does not exist")
    image = cv2.imread(str(path), flags)
    if image is None:
        raise InputFileError(f"{path}: {field} is not a readable PNG image")
    return image


# --- loading --------------------------------------------------------------------------------


def load_sequence(path: str | os.PathLike) -> Sequence:
    """Load and validate the sequence folder ``path`` (or its ``sequence.json``)."""
    path = Path(path)
    root = path.parent if path.name == "sequence.json" else path
    jpath = root / "sequence.json"
    if not jpath.is_file():
        raise InputFileError(f"{jpath}: sequence.json does not exist (expected a {FORMAT} folder)")
    try:
        doc = json.loads(jpath.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputFileError(f"{jpath}: not valid JSON ({e})") from None
    if not isinstance(doc, dict):
        raise InputFileError(f"{jpath}: top level must be a JSON object")

    def fail(field: str, msg: str):
        raise InputFileError(f"{jpath}: field {field!r} {msg}")

    if doc.get("format") != FORMAT:
        fail("format", f"must be {FORMAT!r}, got {doc.get('format')!r}")
    gravity = _vector(doc.get("gravity", [0.0, 0.0, -9.81]), 3, "gravity", fail)
    scale = doc.get("depth_scale")
    if not _is_number(scale) or not scale > 0:
        fail("depth_scale", f"must be a positive number (PNG value per metre), got {scale!r}")
    cams = doc.get("cameras")
    if not isinstance(cams, dict) or not cams:
        fail("cameras", "must be a non-empty object of camera name -> intrinsics")
    cameras = {name: _camera(name, c, fail) for name, c in cams.items()}
    frames_doc = doc.get("frames")
    if not isinstance(frames_doc, list) or not frames_doc:
        fail("frames", "must be a non-empty list")
    frames, seen = [], set()
    for i, fd in enumerate(frames_doc):
        f = _frame(i, fd, cameras, root, fail)
        if f.index in seen:
            fail(f"frames[{i}].index", f"repeats index {f.index}")
        seen.add(f.index)
        frames.append(f)
    wpath = root / "wrenches.csv"
    wrenches = read_wrenches(wpath) if wpath.exists() else None
    return Sequence(root, gravity, float(scale), cameras, tuple(frames), wrenches)


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def _vector(value, n: int, field: str, fail) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n or not all(_is_number(x) for x in value):
        fail(field, f"must be a list of {n} finite numbers, got {value!r}")
    return np.array(value, dtype=float)


def _camera(name: str, c, fail) -> CameraInfo:
    field = f"cameras.{name}"
    if not isinstance(c, dict):
        fail(field, "must be an object with width, height, fx, fy, cx, cy")
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        if key not in c:
            fail(f"{field}.{key}", "is missing")
        v = c[key]
        if not _is_number(v):
            fail(f"{field}.{key}", f"must be a finite number, got {v!r}")
        if key in ("width", "height") and (int(v) != v or v <= 0):
            fail(f"{field}.{key}", f"must be a positive integer, got {v!r}")
        if key in ("fx", "fy") and not v > 0:
            fail(f"{field}.{key}", f"must be positive, got {v!r}")
    return CameraInfo(name, int(c["width"]), int(c["height"]), float(c["fx"]), float(c["fy"]), float(c["cx"]), float(c["cy"]))


def _frame(i: int, fd, cameras: dict, root: Path, fail) -> Frame:
    field = f"frames[{i}]"
    if not isinstance(fd, dict):
        fail(field, "must be an object")
    for key in ("index", "t", "camera", "T_world_camera", "rgb", "depth"):
        if key not in fd:
            fail(f"{field}.{key}", "is missing")
    index = fd["index"]
    if not isinstance(index, int) or isinstance(index, bool) or index < 0:
        fail(f"{field}.index", f"must be a non-negative integer, got {index!r}")
    if not _is_number(fd["t"]):
        fail(f"{field}.t", f"must be a finite number of seconds, got {fd['t']!r}")
    if fd["camera"] not in cameras:
        fail(f"{field}.camera", f"names camera {fd['camera']!r}, which is not in cameras ({', '.join(sorted(cameras))})")
    T = np.array(fd["T_world_camera"], dtype=object)
    if T.shape != (4, 4) or not all(_is_number(x) for x in T.ravel()):
        fail(f"{field}.T_world_camera", "must be a 4×4 list of finite numbers")
    T = T.astype(float)
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0 or not np.allclose(T[3], [0, 0, 0, 1]):
        fail(f"{field}.T_world_camera", "must be a rigid transform (orthonormal rotation, last row 0 0 0 1)")
    for key in ("rgb", "depth"):
        if not isinstance(fd[key], str) or not fd[key]:
            fail(f"{field}.{key}", f"must be a path relative to the sequence folder, got {fd[key]!r}")
        if not (root / fd[key]).is_file():
            raise InputFileError(f"{root / fd[key]}: file named by field '{field}.{key}' does not exist")
    T.setflags(write=False)
    return Frame(index, float(fd["t"]), fd["camera"], T, fd["rgb"], fd["depth"])


def read_wrenches(path: str | os.PathLike) -> Wrenches:
    """Read ``wrenches.csv`` (t,px,py,pz,fx,fy,fz); errors name the file, column and row."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: wrenches file does not exist")
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    if not rows or tuple(h.strip() for h in rows[0]) != WRENCH_COLUMNS:
        raise InputFileError(f"{path}: header must be {','.join(WRENCH_COLUMNS)}, got {','.join(rows[0]) if rows else '(empty file)'}")
    data = np.empty((len(rows) - 1, 7))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != 7:
            raise InputFileError(f"{path}: row {r} has {len(row)} values, expected 7")
        for c, (name, cell) in enumerate(zip(WRENCH_COLUMNS, row)):
            try:
                data[r - 2, c] = float(cell)
            except ValueError:
                raise InputFileError(f"{path}: column {name!r} row {r} is not a number: {cell!r}") from None
    if not np.all(np.isfinite(data)):
        r, c = np.argwhere(~np.isfinite(data))[0]
        raise InputFileError(f"{path}: column {WRENCH_COLUMNS[c]!r} row {r + 2} is not finite")
    if np.any(np.diff(data[:, 0]) < 0):
        raise InputFileError(f"{path}: column 't' must be non-decreasing")
    return Wrenches(data[:, 0], data[:, 1:4], data[:, 4:7])


# --- writing --------------------------------------------------------------------------------


def frame_paths(camera: str, index: int) -> tuple[str, str]:
    """(rgb, depth) paths of a frame relative to the sequence folder."""
    return f"rgb/{camera}/{index:06d}.png", f"depth/{camera}/{index:06d}.png"


def write_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an 8- or 16-bit image as PNG atomically (3-channel images are given as RGB)."""
    path = Path(path)
    img = np.ascontiguousarray(image)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_RGB2BGR) if img.ndim == 3 else img)
    if not ok:
        raise OSError(f"could not encode {path} as PNG")
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return path


def depth_to_png(depth_m: np.ndarray, depth_scale: float) -> np.ndarray:
    """(H, W) depth [m] (0 or NaN = no reading) -> uint16 PNG values; depths beyond the 16-bit
    range become 0 (no reading)."""
    d = np.nan_to_num(np.asarray(depth_m, dtype=float), nan=0.0) * depth_scale
    d = np.round(d)
    d[(d < 0) | (d > 65535)] = 0
    return d.astype(np.uint16)


def write_sequence_json(root: str | os.PathLike, cameras: dict[str, CameraInfo], frames: list[Frame],
                        depth_scale: float, gravity=(0.0, 0.0, -9.81)) -> Path:
    """Write ``root/sequence.json`` atomically."""
    doc = {
        "format": FORMAT,
        "gravity": [float(g) for g in gravity],
        "depth_scale": float(depth_scale),
        "cameras": {n: {"width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy}
                    for n, c in cameras.items()},
        "frames": [{"index": f.index, "t": f.t, "camera": f.camera,
                    "T_world_camera": np.asarray(f.T_world_camera, dtype=float).tolist(),
                    "rgb": f.rgb, "depth": f.depth} for f in frames],
    }
    path = Path(root) / "sequence.json"
    write_text_atomic(path, json.dumps(doc, indent=1))
    return path


def write_wrenches(path: str | os.PathLike, wrenches: Wrenches) -> Path:
    """Write ``wrenches.csv`` atomically (full float precision)."""
    data = np.column_stack([wrenches.t, wrenches.points_world, wrenches.forces_world])
    return write_numeric_csv_atomic(path, WRENCH_COLUMNS, data)
