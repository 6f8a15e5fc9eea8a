"""The committed hand model and basic shapes: schema-valid and consistent with conventions."""

import json

import jsonschema
import numpy as np
import pytest

from handdb_blender import kinematics
from handdb_blender.plan import REPO_ROOT, check_hand_model, sha256_file

DOF_ORDER = ["thumb_cmc_flexion", "thumb_cmc_abduction", "thumb_mcp_flexion", "thumb_ip_flexion"] + [
    f"{f}_{j}" for f in ("index", "middle", "ring", "pinky")
    for j in ("mcp_flexion", "mcp_abduction", "pip_flexion", "dip_flexion")]
KEYPOINT_ORDER = ["wrist", "thumb_cmc", "thumb_mcp", "thumb_ip", "thumb_tip"] + [
    f"{f}_{j}" for f in ("index", "middle", "ring", "pinky") for j in ("mcp", "pip", "dip", "tip")]


def load(rel):
    with open(f"{REPO_ROOT}/{rel}") as f:
        return json.load(f)


@pytest.fixture(scope="module")
def model():
    return load("configs/hands/webxr_generic_right.json")


@pytest.fixture(scope="module")
def shapes():
    return load("configs/shapes/basic.json")


def test_model_matches_schema_and_semantic_checks(model):
    jsonschema.validate(model, load("schemas/hand_model.schema.json"))
    check_hand_model(model, "hand model")


def test_schema_rejects_a_broken_model(model):
    bad = json.loads(json.dumps(model))
    del bad["dofs"][3]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, load("schemas/hand_model.schema.json"))


def test_asset_hash_matches(model):
    assert sha256_file(f"{REPO_ROOT}/{model['asset']['path']}") == model["asset"]["sha256"]


def test_dof_and_keypoint_order_follow_conventions(model):
    assert [d["name"] for d in model["dofs"]] == DOF_ORDER
    assert [d["index"] for d in model["dofs"]] == list(range(20))
    assert [k["name"] for k in model["keypoints"]] == KEYPOINT_ORDER
    for d in model["dofs"]:
        assert d["min"] <= 0.0 <= d["max"], d["name"]  # the rest pose is inside the limits


def test_links_follow_design_ids(model):
    names = {link["id"]: link["name"] for link in model["links"]}
    assert names[1] == "palm" and names[2] == "thumb1" and names[16] == "pinky3"
    bone_link = {b["name"]: b["link"] for b in model["bones"]}
    for link in model["links"]:
        for bone in link["bones"]:
            assert bone_link[bone] == link["id"]
    assert sorted(bone_link) == sorted(b for link in model["links"] for b in link["bones"])
    assert bone_link["wrist"] == 1 and bone_link["thumb-tip"] == 4 and bone_link["index-finger-tip"] == 7


def test_joint_pairs_are_parent_child_links(model):
    bones = {b["name"]: b for b in model["bones"]}
    pairs = set()
    for b in model["bones"]:
        if b["parent"] is not None and bones[b["parent"]]["link"] != b["link"]:
            pairs.add((bones[b["parent"]]["link"], b["link"]))
    assert pairs == {tuple(p) for p in model["joint_pairs"]}
    assert len(pairs) == 15


def test_reference_axes(model):
    f, n = np.array(model["forward_axis"]), np.array(model["palm_normal"])
    assert abs(f @ n) < 1e-9
    kp = kinematics.keypoints(model, np.zeros(20))
    wrist_to_mcp = kp[9] - kp[0]
    assert wrist_to_mcp @ f / np.linalg.norm(wrist_to_mcp) > 0.99


def test_shapes_valid_and_within_limits(model, shapes):
    jsonschema.validate(shapes, load("schemas/shapes.schema.json"))
    names = [s["name"] for s in shapes["shapes"]]
    assert len(names) >= 26 and len(set(names)) == len(names)
    assert [s["id"] for s in shapes["shapes"]] == list(range(len(names)))
    for required in [f"asl-{i}" for i in range(10)] + ["fist", "flat", "claw", "pinch", "L", "Y", "I-love-you",
                                                         "thumbs-up"]:
        assert required in names
    for s in shapes["shapes"]:
        assert kinematics.within_limits(model, s["joints"]) == [], s["name"]


def _tip_distance(model, joints, tip):
    kp = kinematics.keypoints(model, joints)
    return float(np.linalg.norm(kp[4] - kp[tip]))


def _extended(joints, finger):
    # Up rather than folded: every flexion under 35 deg (a fold is 85-100 deg at MCP and PIP; the
    # ASL digits fitted to real photos keep 20-30 deg of PIP flexion in the fingers that are up).
    base = 4 + 4 * finger
    return joints[base] < 0.6 and joints[base + 2] < 0.6 and joints[base + 3] < 0.6


def test_asl_numbers_follow_their_description(model, shapes):
    s = {x["name"]: x["joints"] for x in shapes["shapes"]}
    ext = {n: [_extended(s[n], f) for f in range(4)] for n in s}
    assert ext["asl-1"] == [True, False, False, False]
    assert ext["asl-2"] == [True, True, False, False]
    assert ext["asl-3"] == [True, True, False, False] and s["asl-3"][0] < 0.1  # thumb out
    assert ext["asl-4"] == [True, True, True, True] and s["asl-4"][0] > 0.6    # thumb folded in
    assert ext["asl-5"] == [True, True, True, True] and s["asl-5"][0] <= 0.0
    # 6-9: the thumb tip goes to the pinky, ring, middle, index tip; the other fingers are up. The
    # shapes fitted to real photos (docs/hand_model.md) bring the thumb within 5 cm of that tip and
    # nearer to it than to any other fingertip; they do not all close the gap (in 2D the pads
    # overlap the thumb before they touch it).
    tips = (8, 12, 16, 20)
    for name, finger, tip in (("asl-6", 3, 20), ("asl-7", 2, 16), ("asl-8", 1, 12), ("asl-9", 0, 8)):
        assert _tip_distance(model, s[name], tip) < 0.05, name
        assert min(tips, key=lambda t: _tip_distance(model, s[name], t)) == tip, name
        assert [e for f, e in enumerate(ext[name]) if f != finger] == [True] * 3, name
        assert not ext[name][finger]
    # the O: the thumb nearest the index tip
    assert _tip_distance(model, s["asl-0"], 8) < 0.04
    assert min(tips, key=lambda t: _tip_distance(model, s["asl-0"], t)) == 8
    assert not any(ext["asl-0"]) and not any(ext["fist"])
    assert all(ext["flat"])
