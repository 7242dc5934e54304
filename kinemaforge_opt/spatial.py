"""SE(3) / SO(3) / screw maths in numpy.

Conventions: ``T_a_b`` is frame b expressed in frame a (``p_a = T_a_b @ p_b``); batches are
plural with the batch axis first (``Ts_world_part``: (T, 4, 4)).  Angles in radians.
"""

from __future__ import annotations

import numpy as np


def skew(w: np.ndarray) -> np.ndarray:
    """(3,) -> (3, 3) matrix with ``skew(w) @ x == cross(w, x)``."""
    x, y, z = np.asarray(w, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vector along ``v``; raises ValueError for a zero vector."""
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if not n > 1e-12:
        raise ValueError("cannot normalise a zero vector")
    return v / n


def tangent_basis(a: np.ndarray) -> np.ndarray:
    """(3, 2) orthonormal basis of the plane perpendicular to the unit vector ``a`` (3,)."""
    helper = np.eye(3)[np.argmin(np.abs(a))]
    u = normalize(np.cross(a, helper))
    return np.stack([u, np.cross(a, u)], axis=1)


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vector (3,) [rad] -> rotation matrix (3, 3)."""
    w = np.asarray(w, dtype=float)
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-9:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * K @ K


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> rotation vector (3,) [rad], angle in [0, pi]."""
    R = np.asarray(R, dtype=float)
    c = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    th = np.arccos(c)
    if th < 1e-9:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    if np.pi - th < 1e-6:
        # Near pi: axis from the symmetric part, R = 2 a a^T - I.
        B = (R + np.eye(3)) / 2
        a = normalize(B[np.argmax(np.diag(B))])
        return th * a
    return th / (2 * np.sin(th)) * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes X, then Y, then Z) -> rotation matrix: Rz(y) Ry(p) Rx(r)."""
    r, p, y = np.asarray(rpy, dtype=float)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix` (pitch in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=float)
    p = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    if abs(np.cos(p)) > 1e-9:
        r = np.arctan2(R[2, 1], R[2, 2])
        y = np.arctan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: put everything in yaw
        r = 0.0
        y = np.arctan2(-R[0, 1], R[1, 1])
    return np.array([r, p, y])


def make_transform(R: np.ndarray | None = None, p: np.ndarray | None = None) -> np.ndarray:
    """(3, 3) rotation and (3,) translation -> (4, 4) homogeneous transform."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def inverse(T_a_b: np.ndarray) -> np.ndarray:
    """T_a_b -> T_b_a for one (4, 4) transform or a batch (N, 4, 4)."""
    T = np.asarray(T_a_b, dtype=float)
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    out[..., 3, 3] = 1.0
    return out


def transform_points(T_a_b: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """Apply (4, 4) ``T_a_b`` to (N, 3) points in frame b -> (N, 3) points in frame a."""
    P = np.asarray(points_b, dtype=float)
    return P @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def rms_radius(points: np.ndarray) -> float:
    """RMS distance [m] of (N, 3) ``points`` from their centroid (a point set's spread)."""
    P = np.asarray(points, dtype=float)
    return float(np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=1))))


def screw_motion(axis: np.ndarray, point: np.ndarray, angle: float, pitch: float = 0.0) -> np.ndarray:
    """Rigid motion (4, 4) of a screw about the line (point, unit axis): rotate by ``angle`` [rad]
    and translate ``pitch * angle`` [m] along the axis.  ``pitch = inf`` is not allowed; use
    :func:`translation_motion` for prismatic motion."""
    a = normalize(axis)
    R = exp_so3(a * angle)
    p = np.asarray(point, dtype=float)
    return make_transform(R, p - R @ p + pitch * angle * a)


def translation_motion(axis: np.ndarray, distance: float) -> np.ndarray:
    """Pure translation (4, 4) by ``distance`` [m] along ``axis``."""
    return make_transform(None, normalize(axis) * distance)


def closest_point_on_line(axis: np.ndarray, point: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The point of the line (point, axis) closest to ``x`` (3,)."""
    a = normalize(axis)
    p = np.asarray(point, dtype=float)
    return p + a * np.dot(np.asarray(x, dtype=float) - p, a)


def line_point_distance(axis: np.ndarray, point: np.ndarray, x: np.ndarray) -> float:
    """Distance [m] from ``x`` (3,) to the line through ``point`` along ``axis``."""
    return float(np.linalg.norm(np.asarray(x, dtype=float) - closest_point_on_line(axis, point, x)))


def axis_angle_error(a: np.ndarray, b: np.ndarray, directed: bool = False) -> float:
    """Angle [rad] between two axes; undirected (a ≡ -a) unless ``directed``."""
    c = float(np.dot(normalize(a), normalize(b)))
    if not directed:
        c = abs(c)
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def line_distance(axis_a, point_a, axis_b, point_b) -> float:
    """Shortest distance [m] between two lines (parallel lines handled)."""
    a, b = normalize(axis_a), normalize(axis_b)
    d = np.asarray(point_b, dtype=float) - np.asarray(point_a, dtype=float)
    n = np.cross(a, b)
    if np.linalg.norm(n) < 1e-9:
        return float(np.linalg.norm(d - a * np.dot(d, a)))
    return float(abs(np.dot(d, normalize(n))))
