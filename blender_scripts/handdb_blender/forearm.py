"""The forearm of photo-like test renders (photo.py), without bpy so pytest checks it.

Real photos of hands show part of the forearm, cut by the picture's border; the database's
renders and the test set's label renders show the hand alone. A test set with `photo.forearm`
adds an elliptic cone to its photos: its cross-section at the wrist is the hand mesh's own
(wrist_section), it starts FOREARM_START inside the hand (covering the asset's short wrist stub
without a seam) and runs FOREARM_LENGTH away from the wrist along -forward_axis, widening by
FOREARM_TAPER towards the elbow, out of the frame (the view is ortho_scale = 0.3 across).
"""

from __future__ import annotations

import math
from typing import List, Sequence, Tuple

import numpy as np

FOREARM_START = 0.015
FOREARM_LENGTH = 0.35
FOREARM_TAPER = (1.15, 1.25)  # lateral, dorsal-palmar
FOREARM_SEGMENTS = 32


def wrist_section(vertices: np.ndarray, wrist: Sequence[float], forward: Sequence[float],
                  palm_normal: Sequence[float], band: float = 0.01) -> Tuple[np.ndarray, float, float]:
    """Centre and semi-axes (lateral, palm-normal) of the hand mesh's cross-section at the wrist:
    the vertices within `band` of the plane through the wrist joint normal to the forward axis.
    Pure numpy (tested without Blender)."""
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f)
    n = np.asarray(palm_normal, float)
    n = n - f * (n @ f)
    n = n / np.linalg.norm(n)
    lat = np.cross(f, n)
    rel = np.asarray(vertices, float) - np.asarray(wrist, float)
    near = np.abs(rel @ f) <= band
    if near.sum() < 8:
        raise ValueError(f"only {int(near.sum())} mesh vertices near the wrist plane")
    sec = rel[near]
    u, v = sec @ lat, sec @ n
    centre = np.asarray(wrist, float) + lat * (u.max() + u.min()) / 2 + n * (v.max() + v.min()) / 2
    return centre, (u.max() - u.min()) / 2, (v.max() - v.min()) / 2


def forearm_vertices(centre: Sequence[float], a: float, b: float, forward: Sequence[float],
                     palm_normal: Sequence[float]) -> Tuple[List[tuple], List[tuple]]:
    """Vertices and quad/ngon faces of the forearm cone (hand frame): rings at +FOREARM_START and
    -FOREARM_LENGTH along the forward axis, closed at both ends."""
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f)
    n = np.asarray(palm_normal, float)
    n = n - f * (n @ f)
    n = n / np.linalg.norm(n)
    lat = np.cross(f, n)
    c = np.asarray(centre, float)
    verts: List[tuple] = []
    for t, (sa, sb) in ((FOREARM_START, (1.0, 1.0)), (-FOREARM_LENGTH, FOREARM_TAPER)):
        for k in range(FOREARM_SEGMENTS):
            ang = 2 * math.pi * k / FOREARM_SEGMENTS
            p = c + f * t + lat * (a * sa * math.cos(ang)) + n * (b * sb * math.sin(ang))
            verts.append(tuple(p))
    s = FOREARM_SEGMENTS
    faces: List[tuple] = [(k, (k + 1) % s, s + (k + 1) % s, s + k) for k in range(s)]
    faces.append(tuple(range(s - 1, -1, -1)))
    faces.append(tuple(range(s, 2 * s)))
    return verts, faces
