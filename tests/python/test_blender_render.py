"""Integration test: the real Blender renders a tiny plan with blender_scripts/render.py.

Checks the EXRs (exact link ids, every link of the open hand seen from the palm, hand inside
the frame, finite depth), the sidecars (agree with the plan, keypoints on the right links),
the roll convention (a rolled render is the roll-0 render rotated), and the unit protocol
(rendered lines, skip on rerun, --frames-per-process restarts, DONE, one-line errors).
Needs `blender` on PATH (or HANDDB_BLENDER); a few seconds of rendering.
"""

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(REPO, "blender_scripts"))

from handdb_blender import camera, exr, kinematics, testplan  # noqa: E402
from handdb_blender.plan import read_json  # noqa: E402

BLENDER = os.environ.get("HANDDB_BLENDER") or shutil.which("blender")
RENDER_PY = os.path.join(REPO, "blender_scripts", "render.py")
MODEL = read_json(os.path.join(REPO, "configs/hands/webxr_generic_right.json"))
ROLL = 0.6
pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender not installed")


def run_render(plan_path, unit, out, *extra):
    cmd = [BLENDER, "-b", "--factory-startup", "-noaudio", "-t", "1", "-P", RENDER_PY, "--",
           "--plan", plan_path, "--unit", str(unit), "--out", out, *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def rendered_ids(stdout):
    return [int(line.split()[1]) for line in stdout.splitlines() if line.startswith("rendered ")]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("render"))
    shapes = {s["name"]: s for s in testplan.basic_shapes()}
    palm = MODEL["palm_normal"]
    dirs = [palm, [-x for x in palm], MODEL["forward_axis"], [0.5, -0.6, 0.62]]
    plan = testplan.make_plan([shapes["flat"], shapes["fist"]], dirs, unit_size=12, rolls=(0.0, ROLL))
    plan_path = os.path.join(out, "plan.json")
    with open(plan_path, "w") as f:
        json.dump(plan, f)
    first = run_render(plan_path, 0, out)
    assert first.returncode == 0, first.stderr[-2000:]
    items = {}
    for item in plan["units"][0]["renders"]:
        base = os.path.join(out, "units", "u00000", f"r{item['render_id']:06d}")
        labels, depth = exr.read_labels_depth(base + ".exr")
        with open(base + ".json") as f:
            side = json.load(f)
        items[item["render_id"]] = (item, labels, depth, side)
    return {"out": out, "plan": plan, "plan_path": plan_path, "first": first, "items": items}


def find(run, shape_name, dir_id, roll):
    for item, labels, depth, side in run["items"].values():
        if side["shape_name"] == shape_name and item["dir_id"] == dir_id and item["roll"] == roll:
            return item, labels, depth, side
    raise KeyError((shape_name, dir_id, roll))


def test_unit_complete_and_progress_lines(run):
    assert sorted(rendered_ids(run["first"].stdout)) == list(range(12))
    assert os.path.exists(os.path.join(run["out"], "units", "u00000", "DONE"))
    leftovers = [n for n in os.listdir(os.path.join(run["out"], "units", "u00000")) if n.endswith(".tmp")]
    assert leftovers == []


def test_labels_are_exact_link_ids(run):
    for item, labels, depth, side in run["items"].values():
        assert labels.shape == (256, 256)
        assert set(np.unique(labels)) <= set(range(17))
        assert (labels > 0).sum() > 2000  # the hand is there


def test_open_hand_from_the_palm_shows_every_link(run):
    _, labels, _, _ = find(run, "flat", 0, 0.0)
    counts = np.bincount(labels.ravel(), minlength=17)
    assert all(counts[link] >= 20 for link in range(1, 17)), counts


def test_hand_inside_the_frame_with_margin(run):
    margin = 256 // 20
    for item, labels, depth, side in run["items"].values():
        ys, xs = np.nonzero(labels)
        assert xs.min() >= margin and ys.min() >= margin, item
        assert xs.max() < 256 - margin and ys.max() < 256 - margin, item


def test_depth_finite_on_the_hand(run):
    for item, labels, depth, side in run["items"].values():
        hand = labels > 0
        assert np.isfinite(depth[hand]).all()
        # Camera 1.0 from the look-at point; the hand lies within ortho_scale of it.
        assert depth[hand].min() > 1.0 - 0.3 and depth[hand].max() < 1.0 + 0.3
        assert (depth[~hand] > 1e3).all()


def test_sidecar_agrees_with_the_plan(run):
    schema = read_json(os.path.join(REPO, "schemas", "render_sidecar.schema.json"))
    import jsonschema

    for item, labels, depth, side in run["items"].values():
        jsonschema.validate(side, schema)
        assert side["render_id"] == item["render_id"] and side["unit"] == 0
        assert side["shape_id"] == item["shape_id"] and side["dir_id"] == item["dir_id"]
        assert side["joint_angles"] == item["joints"]
        assert np.allclose(side["view_direction"], item["direction"])
        assert side["camera_roll"] == item["roll"]
        assert side["resolution"] == 256 and side["ortho_scale"] == pytest.approx(0.3)
        assert side["hand_model_sha256"] == run["plan"]["hand_model"]["sha256"]
        assert side["blender_version"].startswith("3.") and side["script_version"] == "1"
        t, p = camera.view_angles(item["direction"])
        assert side["view_theta"] == pytest.approx(t) and side["view_phi"] == pytest.approx(p)


def test_keypoints_match_python_kinematics(run):
    for item, labels, depth, side in run["items"].values():
        kp = kinematics.keypoints(MODEL, item["joints"])
        r = camera.cam_from_hand_rotation(item["direction"], MODEL["forward_axis"], MODEL["palm_normal"],
                                          item["roll"])
        cam, px = camera.project(kp, MODEL["look_at"], r, 256, 0.3)
        assert np.allclose(side["keypoints_cam"], cam, atol=1e-5)
        assert np.allclose(side["keypoints_px"], px, atol=1e-3)


def test_keypoints_project_onto_their_links(run):
    """Visible keypoints (surface depth close to the keypoint) land on (within 2 px of) a pixel of
    their link; a joint keypoint may also land on the link on the other side of the joint."""
    links = [k["link"] for k in MODEL["keypoints"]]
    parent_link = {child: parent for parent, child in MODEL["joint_pairs"]}
    px_per_unit = 256 / 0.3
    checked = 0
    for item, labels, depth, side in run["items"].values():
        for k, (u, v, z) in enumerate(side["keypoints_px"]):
            i, j = int(math.floor(v)), int(math.floor(u))
            win_l = labels[max(0, i - 2):i + 3, max(0, j - 2):j + 3]
            win_d = depth[max(0, i - 2):i + 3, max(0, j - 2):j + 3]
            kp_depth = 1.0 + z / px_per_unit
            visible = np.isfinite(win_d).any() and win_d.min() > kp_depth - 0.012
            if not visible:
                continue
            ok = {links[k]}
            if links[k] in parent_link and k not in (0,):
                ok.add(parent_link[links[k]])
            assert ok & set(np.unique(win_l)), (item["render_id"], k, set(np.unique(win_l)))
            checked += 1
    assert checked > 100


def rotate_labels(labels, angle):
    import cv2

    h, w = labels.shape
    c, s = math.cos(angle), math.sin(angle)
    # cv2 pixel coordinates have pixel centres at integers, ours at +0.5: centre (w/2-0.5, h/2-0.5).
    cx, cy = w / 2 - 0.5, h / 2 - 0.5
    m = np.array([[c, -s, cx - c * cx + s * cy], [s, c, cy - s * cx - c * cy]])
    return cv2.warpAffine(labels, m, (w, h), flags=cv2.INTER_NEAREST, borderValue=0)


def test_rolled_render_is_the_rotated_unrolled_render(run):
    import cv2

    pairs = {(side["shape_name"], item["dir_id"]) for item, _, _, side in run["items"].values()}
    assert len(pairs) == 6
    for shape, dir_id in sorted(pairs):
        _, l0, _, s0 = find(run, shape, dir_id, 0.0)
        _, la, _, sa = find(run, shape, dir_id, ROLL)
        rotated = rotate_labels(l0, ROLL)
        hand = (rotated > 0) | (la > 0)
        agree = (rotated == la)[hand].mean()
        # Nearest-neighbour resampling differs only at label boundaries: away from them
        # (3x3 neighbourhood of one label in the rolled render) the two must agree exactly.
        away = cv2.morphologyEx(la, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) == 0
        agree_away = (rotated == la)[hand & away].mean()
        assert agree > 0.9 and agree_away > 0.995, (shape, dir_id, agree, agree_away)
        wrong_way = (rotate_labels(l0, -ROLL) == la)[hand].mean()
        assert wrong_way < 0.5, (shape, dir_id, wrong_way)
        kp0 = np.array(s0["keypoints_px"])
        expect = camera.rotate_image_points(kp0[:, :2], ROLL, (128.0, 128.0))
        assert np.allclose(np.array(sa["keypoints_px"])[:, :2], expect, atol=1e-3)


def test_rerun_skips_and_frames_per_process_restarts(run):
    again = run_render(run["plan_path"], 0, run["out"])
    assert again.returncode == 0 and rendered_ids(again.stdout) == []
    # 4 items, a fresh Blender every 3 renders: one process renders 3, re-executes, the next 1.
    part = run_render(run["plan_path"], 1, run["out"], "--frames-per-process", "3", "--timing")
    assert part.returncode == 0, part.stderr[-2000:]
    assert rendered_ids(part.stdout) == [12, 13, 14, 15]
    timings = [line for line in part.stdout.splitlines() if line.startswith("timing ")]
    assert [t.split()[-1] for t in timings] == ["renders=3", "renders=1"]
    assert os.path.exists(os.path.join(run["out"], "units", "u00001", "DONE"))


def test_bad_input_is_one_line_and_nonzero(run, tmp_path):
    missing = run_render(str(tmp_path / "missing.json"), 0, str(tmp_path))
    assert missing.returncode == 1
    assert missing.stderr.strip().splitlines()[-1].startswith("handdb-render: ")
    assert "missing.json: file not found" in missing.stderr
    unknown = run_render(run["plan_path"], 99, str(tmp_path))
    assert unknown.returncode == 1 and "no unit with id 99" in unknown.stderr
    usage = subprocess.run([BLENDER, "-b", "--factory-startup", "-noaudio", "-P", RENDER_PY, "--", "--unit", "0"],
                           capture_output=True, text=True, timeout=120)
    assert usage.returncode == 2
