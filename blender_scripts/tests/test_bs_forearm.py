"""The forearm of photo-like test renders (handdb_blender/forearm.py), without Blender."""
import math

import numpy as np
import pytest

from handdb_blender import forearm

FWD = [0.0, 0.0, -1.0]   # the shipped hand's forward_axis
PALM = [-1.0, 0.0, 0.0]  # its palm_normal


def _elliptic_tube(centre, a, b, z_from, z_to, rings=9, around=40):
    out = []
    for z in np.linspace(z_from, z_to, rings):
        for k in range(around):
            t = 2 * math.pi * k / around
            # lateral = fwd x palm = (0, 1, 0); palm normal = (-1, 0, 0)
            out.append([centre[0] - b * math.sin(t), centre[1] + a * math.cos(t), z])
    return np.array(out)


def test_wrist_section_recovers_the_cross_section():
    wrist = np.array([0.01, 0.02, 0.05])
    centre = wrist + [0.004, -0.003, 0.0]
    verts = _elliptic_tube(centre, 0.03, 0.018, 0.04, 0.06)
    far = _elliptic_tube(centre, 0.08, 0.05, 0.0, 0.02)  # the palm, outside the band: ignored
    c, a, b = forearm.wrist_section(np.vstack([verts, far]), wrist, FWD, PALM)
    assert a == pytest.approx(0.03, abs=1e-6)
    assert b == pytest.approx(0.018, abs=1e-6)
    np.testing.assert_allclose(c, centre, atol=1e-6)


def test_wrist_section_needs_vertices_near_the_wrist():
    with pytest.raises(ValueError, match="near the wrist plane"):
        forearm.wrist_section(np.zeros((3, 3)) + [0, 0, 1.0], [0, 0, 0], FWD, PALM)


def test_forearm_runs_from_inside_the_hand_out_of_the_frame():
    centre = np.array([0.0, 0.0, 0.0])
    verts, faces = forearm.forearm_vertices(centre, 0.03, 0.02, FWD, PALM)
    v = np.array(verts)
    s = forearm.FOREARM_SEGMENTS
    assert v.shape == (2 * s, 3) and len(faces) == s + 2
    t = v @ np.array(FWD)
    np.testing.assert_allclose(t[:s], forearm.FOREARM_START)   # inside the hand, past the wrist
    np.testing.assert_allclose(t[s:], -forearm.FOREARM_LENGTH)  # towards the elbow
    assert forearm.FOREARM_LENGTH > 0.3 / 2 + 0.05                # leaves a 0.3-wide view
    lat = np.abs(v[:, 1]); dors = np.abs(v[:, 0])
    assert lat[:s].max() == pytest.approx(0.03) and dors[:s].max() == pytest.approx(0.02)
    assert lat[s:].max() == pytest.approx(0.03 * forearm.FOREARM_TAPER[0])
    assert dors[s:].max() == pytest.approx(0.02 * forearm.FOREARM_TAPER[1])
    for f in faces[:s]:  # side quads join ring k to ring k + 1 and the far ring
        assert len(f) == 4 and all(0 <= i < 2 * s for i in f)
