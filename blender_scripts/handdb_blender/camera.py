"""Orthographic camera geometry of docs/conventions.md, without bpy.

Frames: hand frame (armature space), camera frame in OpenCV axes (x right, y down, z away from
the camera, origin at the look-at point). Image: pixel centres at integer + 0.5, origin at the
top-left corner of the top-left pixel, so the look-at point projects to (W/2, H/2).
"""

from __future__ import annotations

import math
from typing import Sequence, Tuple

import numpy as np

# Looking (almost) along the fingers: the forward axis no longer gives a stable image up.
POLE_THRESHOLD = 0.99


def _unit(v: Sequence[float], what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(a))
    if not math.isfinite(n) or n < 1e-12:
        raise ValueError(f"{what} must be a non-zero finite 3-vector, got {list(v)}")
    return a / n


def view_angles(direction: Sequence[float]) -> Tuple[float, float]:
    """(theta, phi) of a unit view direction: theta = acos(d.z), phi = atan2(d.y, d.x)."""
    d = _unit(direction, "view direction")
    return math.acos(max(-1.0, min(1.0, d[2]))), math.atan2(d[1], d[0])


def image_up(direction: Sequence[float], forward_axis: Sequence[float],
             palm_normal: Sequence[float]) -> np.ndarray:
    """Unit image-up vector (hand frame) at roll 0: forward_axis projected onto the image plane,
    or -palm_normal projected when |d . forward_axis| > POLE_THRESHOLD."""
    d = _unit(direction, "view direction")
    fwd = _unit(forward_axis, "forward_axis")
    ref = fwd if abs(float(d @ fwd)) <= POLE_THRESHOLD else -_unit(palm_normal, "palm_normal")
    up = ref - (ref @ d) * d
    n = float(np.linalg.norm(up))
    if n < 1e-9:
        raise ValueError("palm_normal is parallel to the view direction at the pole")
    return up / n


def cam_from_hand_rotation(direction: Sequence[float], forward_axis: Sequence[float],
                           palm_normal: Sequence[float], roll: float = 0.0) -> np.ndarray:
    """3x3 R with rows = camera x (right), y (down), z (forward) axes in the hand frame, so
    point_in_cam = R @ (point_in_hand - look_at).

    Roll a rotates the image content by a (x' = cos a x - sin a y, y' = sin a x + cos a y):
    the rolled axes are right' = cos a right - sin a down, down' = sin a right + cos a down.
    """
    d = _unit(direction, "view direction")
    up = image_up(d, forward_axis, palm_normal)
    fwd = -d                      # optical axis, away from the camera
    down = -up
    right = np.cross(down, fwd)   # OpenCV: x = y cross z
    c, s = math.cos(roll), math.sin(roll)
    right_r = c * right - s * down
    down_r = s * right + c * down
    return np.stack([right_r, down_r, fwd])


def blender_camera_matrix(direction: Sequence[float], forward_axis: Sequence[float],
                          palm_normal: Sequence[float], look_at: Sequence[float],
                          distance: float, roll: float = 0.0) -> np.ndarray:
    """4x4 world matrix of a Blender camera (looks along its -Z, +Y up) placed `distance` from
    the look-at point towards `direction`."""
    r = cam_from_hand_rotation(direction, forward_axis, palm_normal, roll)
    right, down, fwd = r
    m = np.eye(4)
    m[:3, 0] = right
    m[:3, 1] = -down
    m[:3, 2] = -fwd
    m[:3, 3] = np.asarray(look_at, dtype=np.float64) + distance * _unit(direction, "view direction")
    return m


def project(points_hand: np.ndarray, look_at: Sequence[float], cam_from_hand: np.ndarray,
            resolution: int, ortho_scale: float) -> Tuple[np.ndarray, np.ndarray]:
    """Camera-frame points (N, 3) and pixels (N, 3) = (u, v, depth_px) for an orthographic
    camera of `ortho_scale` world units across `resolution` pixels (square image)."""
    p = np.asarray(points_hand, dtype=np.float64).reshape(-1, 3)
    cam = (p - np.asarray(look_at, dtype=np.float64)) @ cam_from_hand.T
    px_per_unit = resolution / ortho_scale
    px = np.empty_like(cam)
    px[:, 0] = resolution / 2.0 + cam[:, 0] * px_per_unit
    px[:, 1] = resolution / 2.0 + cam[:, 1] * px_per_unit
    px[:, 2] = cam[:, 2] * px_per_unit
    return cam, px


def rotate_image_points(xy: np.ndarray, angle: float, centre: Tuple[float, float]) -> np.ndarray:
    """Rotates pixel points about `centre` by the roll convention (clockwise on screen)."""
    c, s = math.cos(angle), math.sin(angle)
    q = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - np.asarray(centre)
    out = np.empty_like(q)
    out[:, 0] = c * q[:, 0] - s * q[:, 1]
    out[:, 1] = s * q[:, 0] + c * q[:, 1]
    return out + np.asarray(centre)
