import math

import numpy as np
import pytest

from handdb_blender import kinematics
from handdb_blender.plan import REPO_ROOT, read_json


@pytest.fixture(scope="module")
def model():
    return read_json(f"{REPO_ROOT}/configs/hands/webxr_generic_right.json")


def random_poses(model, n, seed=5):
    lo = np.array([d["min"] for d in model["dofs"]])
    hi = np.array([d["max"] for d in model["dofs"]])
    return lo + (hi - lo) * np.random.default_rng(seed).random((n, 20))


def test_axis_angle_matrix():
    r = kinematics.axis_angle_matrix([0, 0, 2], math.pi / 2)
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])
    for axis in np.random.default_rng(0).normal(size=(20, 3)):
        r = kinematics.axis_angle_matrix(axis, 0.7)
        assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
        assert np.allclose(r @ axis, axis)


def test_zero_pose_keypoints_are_rest_heads(model):
    kp = kinematics.keypoints(model, np.zeros(20))
    heads = {b["name"]: b["head"] for b in model["bones"]}
    for k in model["keypoints"]:
        assert np.allclose(kp[k["index"]], heads[k["bone"]])


def test_posing_keeps_bone_lengths_and_moves_children(model):
    chain = [(0, 1), (1, 2), (2, 3), (3, 4)] + [(a, a + 1) for f in range(4) for a in range(5 + 4 * f, 8 + 4 * f)]
    rest = kinematics.keypoints(model, np.zeros(20))
    for j in random_poses(model, 30):
        kp = kinematics.keypoints(model, j)
        for a, b in chain:
            assert np.linalg.norm(kp[a] - kp[b]) == pytest.approx(np.linalg.norm(rest[a] - rest[b]), abs=1e-6)
        assert np.allclose(kp[0], rest[0])  # the wrist is the root
    j = np.zeros(20)
    j[4] = 1.0  # index MCP flexion moves PIP, DIP and tip, not the MCP itself
    kp = kinematics.keypoints(model, j)
    assert np.allclose(kp[5], rest[5])
    assert all(np.linalg.norm(kp[i] - rest[i]) > 1e-3 for i in (6, 7, 8))


def test_flexion_curls_towards_the_palm_and_abduction_spreads(model):
    palm = np.array(model["palm_normal"])
    rest = kinematics.keypoints(model, np.zeros(20))
    for flex, tip in ((4, 8), (6, 8), (8, 12), (12, 16), (16, 20), (18, 20)):
        j = np.zeros(20)
        j[flex] = 0.5
        assert (kinematics.keypoints(model, j)[tip] - rest[tip]) @ palm > 0.005, flex
    # The thumb flexes across the palm: towards the palm and the little-finger side.
    ulnar = rest[17] - rest[5]
    across = palm + ulnar / np.linalg.norm(ulnar)
    for flex in (0, 2, 3):
        j = np.zeros(20)
        j[flex] = 0.5
        assert (kinematics.keypoints(model, j)[4] - rest[4]) @ across > 0.005, flex
    # Abduction: away from the middle finger (index and ring/pinky opposite ways).
    middle_dir = rest[12] - rest[9]
    for abd, tip, base in ((5, 8, 5), (13, 16, 13), (17, 20, 17)):
        j = np.zeros(20)
        j[abd] = 0.3
        kp = kinematics.keypoints(model, j)
        side = rest[base] - rest[9]
        side -= (side @ middle_dir) / (middle_dir @ middle_dir) * middle_dir
        assert (kp[tip] - rest[tip]) @ side > 0, abd


def test_within_limits(model):
    assert kinematics.within_limits(model, np.zeros(20)) == []
    j = np.zeros(20)
    j[6] = -0.5  # PIP cannot hyperextend
    assert kinematics.within_limits(model, j) == ["index_pip_flexion"]


def test_rejects_wrong_length(model):
    with pytest.raises(ValueError):
        kinematics.keypoints(model, np.zeros(19))
