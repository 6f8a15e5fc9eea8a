"""The bpy-free half of the test-set renderer (handdb_blender/testset.py)."""
import copy
import json
import math
import os

import jsonschema
import pytest

from handdb_blender import plan as planlib
from handdb_blender import testset
from handdb_blender.errors import RenderError


def _schema(name):
    with open(os.path.join(planlib.SCHEMA_DIR, name)) as f:
        return json.load(f)


@pytest.fixture()
def plan():
    items = []
    for i in range(5):
        d = [math.sin(0.3 * i), 0.0, math.cos(0.3 * i)]
        items.append({
            "id": i, "unit": i // 2, "seed": 1000 + i, "basic": i == 0,
            "shape_name": "flat" if i == 0 else f"pca-{i:05d}", "joints": [0.1 * i] * 20,
            "coeffs": [] if i == 0 else [0.5, -0.2], "clamped": False, "direction": d,
            "theta": math.acos(d[2]), "phi": math.atan2(d[1], d[0]), "roll": 0.7 * i,
        })
    return {
        "format": "handdb-testset-plan", "version": 1, "name": "t", "seed": 9, "config": {},
        "hand_model": {"path": "configs/hands/webxr_generic_right.json", "sha256": "a" * 64},
        "forward_axis": [0, 0, -1], "palm_normal": [-1, 0, 0],
        "render": {"resolution": 128, "ortho_scale": 0.3},
        "photo": {"samples": 4, "skin_rgb": [0.8, 0.5, 0.4], "background_rgb": [0.1, 0.1, 0.1],
                  "clutter": False},
        "unit_size": 2, "shapes": {}, "handdb_version": "0", "items": items,
    }


def write(tmp_path, doc):
    p = tmp_path / "testset_plan.json"
    p.write_text(json.dumps(doc))
    return str(p)


def test_plan_loads_and_splits_into_units(tmp_path, plan):
    loaded = testset.load_plan(write(tmp_path, plan))
    assert testset.num_units(loaded) == 3
    assert [it["id"] for it in testset.unit_items(loaded, 1)] == [2, 3]
    assert [it["id"] for it in testset.unit_items(loaded, 2)] == [4]
    with pytest.raises(RenderError, match="unit 3 is not in the plan"):
        testset.unit_items(loaded, 3)


def test_plan_errors_name_the_file_and_item(tmp_path, plan):
    bad = copy.deepcopy(plan)
    bad["items"][3]["unit"] = 0
    with pytest.raises(RenderError, match="item 3"):
        testset.load_plan(write(tmp_path, bad))
    bad = copy.deepcopy(plan)
    bad["format"] = "handdb-plan"
    with pytest.raises(RenderError, match="testset_plan.json"):
        testset.load_plan(write(tmp_path, bad))
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(RenderError, match="broken.json"):
        testset.load_plan(str(tmp_path / "broken.json"))


def test_file_names_follow_the_render_layout():
    assert testset.label_path("/d", 3, 123) == "/d/units/u00003/r000123.exr"
    assert testset.sidecar_path("/d", 3, 123) == "/d/units/u00003/r000123.json"
    assert testset.photo_path("/d", 3, 123) == "/d/photos/u00003/r000123.png"


def test_sidecar_is_a_render_sidecar_of_the_item(plan):
    item = plan["items"][3]
    kp = [[0.01 * k, 0.02, 0.03] for k in range(21)]
    side = testset.make_sidecar(plan, item, kp, kp, "3.4.1")
    jsonschema.validate(side, _schema("render_sidecar.schema.json"))
    assert side["render_id"] == side["shape_id"] == side["dir_id"] == 3
    assert side["unit"] == 1
    assert side["camera_roll"] == pytest.approx(0.7 * 3)
    assert side["joint_angles"] == item["joints"]
    assert side["resolution"] == 128


def test_clutter_and_lights_are_seeded():
    a = testset.clutter_params(42)
    assert a == testset.clutter_params(42)
    assert a != testset.clutter_params(43)
    assert len(a["colours"]) == 4
    for c in a["colours"]:
        assert all(0.0 <= v <= 1.0 for v in c)
    lights = testset.light_params(42)
    assert lights == testset.light_params(42)
    assert 20.0 <= lights["key_pitch_deg"] <= 45.0


def test_colour_helpers():
    assert testset.srgb_to_linear(0.0) == 0.0
    assert testset.srgb_to_linear(1.0) == pytest.approx(1.0)
    assert testset.srgb_to_linear(0.5) == pytest.approx(0.214, abs=1e-3)
    assert testset.check_rgb([0.1, 0.2, 0.3], "x") == [0.1, 0.2, 0.3]
    with pytest.raises(RenderError, match="skin"):
        testset.check_rgb([0.1, 2.0, 0.3], "skin")


def test_forearm_on_some_items(plan):
    # A plan with photo.forearm_fraction marks every item; the studio shows the arm per item.
    plan["photo"]["forearm_fraction"] = 0.5
    for i, item in enumerate(plan["items"]):
        item["forearm"] = i % 2 == 0
    jsonschema.validate(plan, _schema("testset_plan.schema.json"))
    assert testset.uses_forearm(plan["photo"])
    shown = [testset.item_forearm(it, bool(plan["photo"].get("forearm", False))) for it in plan["items"]]
    assert shown == [True, False, True, False, True]


def test_forearm_all_or_none(plan):
    assert not testset.uses_forearm(plan["photo"])
    assert not testset.item_forearm(plan["items"][0], False)
    plan["photo"]["forearm"] = True
    assert testset.uses_forearm(plan["photo"])
    assert testset.item_forearm(plan["items"][0], True)


def test_sequence_items_choose_background_and_shift(tmp_path, plan):
    plan["items"][1]["clutter"] = True
    plan["items"][2]["photo_offset_px"] = [12.5, -3.0]
    plan["items"][2]["sequence"] = {"id": 0, "frame": 2, "time": 2 / 30, "leaving": True}
    plan["sequence"] = {"sequences": 1, "frames": 5}
    jsonschema.validate(plan, _schema("testset_plan.schema.json"))
    path = tmp_path / "testset_plan.json"
    path.write_text(json.dumps(plan))
    loaded = testset.load_plan(str(path))
    assert testset.item_clutter(loaded["items"][1], False) is True
    assert testset.item_clutter(loaded["items"][0], False) is False
    assert testset.item_clutter(loaded["items"][0], True) is True
    assert testset.item_offset_px(loaded["items"][2]) == [12.5, -3.0]
    assert testset.item_offset_px(loaded["items"][0]) == [0.0, 0.0]
    with pytest.raises(RenderError, match="photo_offset_px"):
        testset.item_offset_px({"id": 3, "photo_offset_px": [1.0]})
