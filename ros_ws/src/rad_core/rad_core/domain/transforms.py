"""Rotations as PyBullet and ROS write them: quaternions (x, y, z, w) and 3x3 matrices.

Plain numpy, no PyBullet: physics, the World, GAMP and motion-capture
registration all convert with these, so each formula lives once. Yaw is about
+z, in degrees, as the scene format gives it.
"""

from __future__ import annotations

import math

import numpy as np


def matrix_from_quaternion(q) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion x, y, z, w."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_from_matrix(r: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation matrix (Shepperd's method, safe near 180 deg)."""
    t = np.trace(r)
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(0.0, 1.0 + r[i, i] - r[j, j] - r[k, k]))
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = s / 4
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    return [float(v) for v in q]


def yaw_quaternion(yaw_deg: float) -> tuple[float, float, float, float]:
    """Quaternion x, y, z, w of a turn by yaw_deg about +z."""
    half = math.radians(yaw_deg) / 2
    return (0.0, 0.0, math.sin(half), math.cos(half))


def yaw_matrix(yaw_deg: float) -> np.ndarray:
    """Rotation matrix of a turn by yaw_deg about +z."""
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_of_quaternion(q) -> float:
    """Yaw (deg, in [0, 360)) of a quaternion x, y, z, w that turns about z only."""
    x, y, z, w = q
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))) % 360


def rotation_angle_deg(r: np.ndarray) -> float:
    """Angle (deg) of a rotation matrix, whatever its axis."""
    return math.degrees(math.acos(min(1.0, max(-1.0, (r[0, 0] + r[1, 1] + r[2, 2] - 1.0) / 2.0))))


def quaternion_angle_deg(q1, q2) -> float:
    """Angle (deg) of the rotation between two quaternions x, y, z, w (need not be unit)."""
    d = abs(float(np.dot(q1, q2))) / (np.linalg.norm(q1) * np.linalg.norm(q2))
    return math.degrees(2 * math.acos(min(1.0, d)))
