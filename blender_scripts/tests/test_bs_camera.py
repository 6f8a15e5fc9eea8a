import math

import numpy as np
import pytest

from handdb_blender import camera, kinematics
from handdb_blender.plan import REPO_ROOT, read_json

FWD = [0.0, 0.0, -1.0]
PALM = [-1.0, 0.0, 0.0]


def random_dirs(n, seed=3):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_rotation_is_proper_and_looks_along_minus_direction():
    for d in random_dirs(200):
        for roll in (0.0, 0.4, -2.0):
            r = camera.cam_from_hand_rotation(d, FWD, PALM, roll)
            assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(r) == pytest.approx(1.0)
            assert np.allclose(r[2], -d)


def test_up_is_projected_forward_axis_away_from_the_pole():
    for d in random_dirs(200):
        up = camera.image_up(d, FWD, PALM)
        assert abs(up @ d) < 1e-12
        if abs(d @ np.array(FWD)) <= camera.POLE_THRESHOLD:
            ref = np.array(FWD) - (np.array(FWD) @ d) * d
            assert np.allclose(up, ref / np.linalg.norm(ref))
        r = camera.cam_from_hand_rotation(d, FWD, PALM)
        assert np.allclose(r[1], -up)  # image down is -up


def test_up_uses_minus_palm_normal_at_the_poles():
    for d in ([0, 0, -1], [0, 0, 1], [0.05, 0.0, -0.9987492]):
        d = np.array(d, dtype=float) / np.linalg.norm(d)
        up = camera.image_up(d, FWD, PALM)
        ref = -np.array(PALM) - (-np.array(PALM) @ d) * d
        assert np.allclose(up, ref / np.linalg.norm(ref))


def test_up_is_continuous_away_from_the_pole_threshold():
    # Just inside the threshold the rule still uses forward_axis and stays well defined.
    a = math.acos(camera.POLE_THRESHOLD) + 1e-3
    d = np.array([math.sin(a), 0.0, -math.cos(a)])
    up = camera.image_up(d, FWD, PALM)
    assert np.isfinite(up).all() and np.linalg.norm(up) == pytest.approx(1.0)


def test_roll_rotates_the_image_clockwise_about_the_centre():
    pts = np.random.default_rng(1).uniform(-0.1, 0.1, size=(50, 3))
    look_at = [0.01, 0.02, -0.03]
    for d in random_dirs(20, seed=7):
        r0 = camera.cam_from_hand_rotation(d, FWD, PALM, 0.0)
        _, px0 = camera.project(pts, look_at, r0, 256, 0.3)
        for a in (0.3, math.pi / 2, -1.0, 2 * math.pi / 48 * 7):
            ra = camera.cam_from_hand_rotation(d, FWD, PALM, a)
            _, pxa = camera.project(pts, look_at, ra, 256, 0.3)
            expect = camera.rotate_image_points(px0[:, :2], a, (128.0, 128.0))
            assert np.allclose(pxa[:, :2], expect, atol=1e-9)
            assert np.allclose(pxa[:, 2], px0[:, 2])


def test_roll_quarter_turn_maps_right_to_down():
    # x right, y down: +a turns +x towards +y (clockwise on screen).
    out = camera.rotate_image_points(np.array([[138.0, 128.0]]), math.pi / 2, (128.0, 128.0))
    assert np.allclose(out, [[128.0, 138.0]])


def test_projection_centre_scale_and_depth():
    d = np.array([-1.0, 0.0, 0.0])
    r = camera.cam_from_hand_rotation(d, FWD, PALM)
    look_at = np.array([0.02, 0.0, -0.03])
    pts = np.array([look_at, look_at + 0.1 * np.array(FWD), look_at - 0.05 * d])
    cam, px = camera.project(pts, look_at, r, 200, 0.4)
    assert np.allclose(px[0], [100.0, 100.0, 0.0])
    assert np.allclose(px[1], [100.0, 100.0 - 0.1 * 200 / 0.4, 0.0])  # forward axis is image up
    assert np.allclose(cam[2], [0.0, 0.0, 0.05])                      # away from the camera: +z
    assert px[2][2] == pytest.approx(0.05 * 200 / 0.4)


def test_right_hand_from_the_palm_side_has_the_thumb_on_the_right():
    model = read_json(f"{REPO_ROOT}/configs/hands/webxr_generic_right.json")
    kp = kinematics.keypoints(model, np.zeros(20))
    r = camera.cam_from_hand_rotation(model["palm_normal"], model["forward_axis"], model["palm_normal"])
    _, px = camera.project(kp, model["look_at"], r, 256, model["ortho_scale"])
    assert px[4][0] > px[20][0]       # thumb tip right of the pinky tip
    assert px[12][1] < px[0][1]       # middle tip above the wrist
    r = camera.cam_from_hand_rotation(-np.array(model["palm_normal"]), model["forward_axis"], model["palm_normal"])
    _, px = camera.project(kp, model["look_at"], r, 256, model["ortho_scale"])
    assert px[4][0] < px[20][0]       # from the back: mirrored


def test_view_angles():
    assert camera.view_angles([0, 0, 1]) == pytest.approx((0.0, 0.0))
    t, p = camera.view_angles([0, -1, 0])
    assert t == pytest.approx(math.pi / 2) and p == pytest.approx(-math.pi / 2)


def test_rejects_degenerate_directions():
    with pytest.raises(ValueError):
        camera.cam_from_hand_rotation([0, 0, 0], FWD, PALM)
    with pytest.raises(ValueError):
        camera.cam_from_hand_rotation([float("nan"), 0, 1], FWD, PALM)
