import json
import os

import jsonschema
import pytest

from handdb_blender import plan as planlib
from handdb_blender import testplan
from handdb_blender.errors import RenderError


@pytest.fixture()
def small_plan():
    shapes = testplan.basic_shapes()[:2]
    return testplan.make_plan(shapes, [[0, 0, 1], [1, 0, 0], [0, -1, 0]], unit_size=4)


def write(tmp_path, doc, name="plan.json"):
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return str(p)


def test_hand_made_plan_matches_the_plan_schema(small_plan):
    schema_path = os.path.join(planlib.SCHEMA_DIR, "render_plan.schema.json")
    if not os.path.exists(schema_path):
        pytest.skip("render_plan.schema.json not present")
    with open(schema_path) as f:
        jsonschema.validate(small_plan, json.load(f))
    planlib.check_plan(small_plan, "plan")
    assert [len(u["renders"]) for u in small_plan["units"]] == [4, 2]
    assert [r["render_id"] for u in small_plan["units"] for r in u["renders"]] == list(range(6))


def test_read_json_reports_line_and_column(tmp_path):
    p = write(tmp_path, '{"format": "handdb-plan",\n  "version": 1,,}')
    with pytest.raises(RenderError, match=r"plan.json: line 2, column 16"):
        planlib.read_json(p)


def test_missing_file(tmp_path):
    with pytest.raises(RenderError, match="file not found"):
        planlib.read_json(str(tmp_path / "nope.json"))


def test_schema_violation_names_the_pointer(tmp_path, small_plan):
    small_plan["render"]["resolution"] = "big"
    p = write(tmp_path, small_plan)
    if not os.path.exists(os.path.join(planlib.SCHEMA_DIR, "render_plan.schema.json")):
        pytest.skip("render_plan.schema.json not present")
    with pytest.raises(RenderError, match=r"/render/resolution"):
        planlib.read_json(p, "render_plan.schema.json")


@pytest.mark.parametrize("mutate, message", [
    (lambda p: p.update(format="other"), "/format"),
    (lambda p: p.update(version=2), "unsupported plan version"),
    (lambda p: p["render"].update(resolution=0), "/render/resolution"),
    (lambda p: p["render"].update(ortho_scale=-1.0), "/render/ortho_scale"),
    (lambda p: p["render"].update(engine="eevee"), "/render/engine"),
    (lambda p: p.pop("hand_model"), "/hand_model/path"),
])
def test_check_plan_rejects(small_plan, mutate, message):
    mutate(small_plan)
    with pytest.raises(RenderError, match=message):
        planlib.check_plan(small_plan, "plan.json")


@pytest.mark.parametrize("mutate, message", [
    (lambda u: u["renders"][0].update(joints=[0.0] * 19), "joints: expected 20 numbers"),
    (lambda u: u["renders"][0].update(direction=[0.0, 0.0, 2.0]), "not a unit vector"),
    (lambda u: u["renders"][0].update(direction=[float("nan"), 0.0, 1.0]), "non-finite"),
    (lambda u: u["renders"][1].update(render_id=0), "duplicate 0"),
    (lambda u: u["renders"][0].update(shape_id=-1), "shape_id"),
    (lambda u: u.update(renders=[]), "non-empty list"),
])
def test_find_unit_rejects_bad_items(small_plan, mutate, message):
    mutate(small_plan["units"][0])
    with pytest.raises(RenderError, match=message):
        planlib.find_unit(small_plan, 0, "plan.json")


def test_unknown_unit(small_plan):
    with pytest.raises(RenderError, match="no unit with id 9"):
        planlib.find_unit(small_plan, 9, "plan.json")


def test_hand_model_is_resolved_and_hash_checked(tmp_path, small_plan):
    model, model_path, asset_path = planlib.load_hand_model(small_plan, str(tmp_path / "plan.json"))
    assert model["name"] == "webxr-generic-right" and os.path.exists(asset_path)
    small_plan["hand_model"]["path"] = "configs/hands/webxr_generic_right.json"  # repo-relative
    planlib.load_hand_model(small_plan, str(tmp_path / "plan.json"))
    small_plan["hand_model"]["sha256"] = "0" * 64
    with pytest.raises(RenderError, match="sha256 differs"):
        planlib.load_hand_model(small_plan, str(tmp_path / "plan.json"))
    small_plan["hand_model"]["path"] = "configs/hands/missing.json"
    with pytest.raises(RenderError, match="not found"):
        planlib.load_hand_model(small_plan, str(tmp_path / "plan.json"))


def test_item_paths_and_pending(tmp_path, small_plan):
    unit = small_plan["units"][1]
    exr, side = planlib.item_paths(str(tmp_path), 1, 5)
    assert exr.endswith("units/u00001/r000005.exr") and side.endswith("units/u00001/r000005.json")
    assert [i["render_id"] for i in planlib.pending_items(str(tmp_path), unit)] == [4, 5]
    os.makedirs(os.path.dirname(exr))
    open(exr, "w").close()
    assert [i["render_id"] for i in planlib.pending_items(str(tmp_path), unit)] == [4, 5]  # needs both
    open(side, "w").close()
    assert [i["render_id"] for i in planlib.pending_items(str(tmp_path), unit)] == [4]


def test_atomic_write_leaves_no_temp(tmp_path):
    p = str(tmp_path / "x.json")
    planlib.write_json_atomic(p, {"a": 1})
    assert json.load(open(p)) == {"a": 1} and os.listdir(tmp_path) == ["x.json"]


def test_sidecar_matches_its_schema(small_plan):
    unit = small_plan["units"][0]
    item = unit["renders"][1]
    kp = [[0.1, 0.2, 0.3]] * 21
    side = planlib.sidecar(small_plan, unit, item, "asl-0", kp, kp, "3.4.1", 0.5, -0.2, "a" * 64)
    with open(os.path.join(planlib.SCHEMA_DIR, "render_sidecar.schema.json")) as f:
        schema = json.load(f)
    jsonschema.validate(side, schema)
    assert side["render_id"] == 1 and side["dir_id"] == 1 and side["joint_angles"] == item["joints"]
    del side["keypoints_px"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(side, schema)


def test_fibonacci_directions_are_unit_and_spread():
    import numpy as np

    d = np.array(testplan.fibonacci_directions(86))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert abs(d.mean(axis=0)).max() < 0.02


def test_render_entry_point_rejects_a_bad_plan_before_starting(tmp_path, small_plan):
    """render.py's run() validates the plan (schema + semantics) before it needs bpy."""
    import argparse

    import render

    if not os.path.exists(os.path.join(planlib.SCHEMA_DIR, "render_plan.schema.json")):
        pytest.skip("render_plan.schema.json not present")
    small_plan["units"][0]["renders"][0]["joints"][3] = 7.0  # outside the schema's joint range
    p = write(tmp_path, small_plan)
    args = argparse.Namespace(plan=p, unit=0, out=str(tmp_path), frames_per_process=0, timing=False)
    with pytest.raises(RenderError, match=r"/units/0/renders/0/joints/3"):
        render.run(args)
    args.unit = 1
    with pytest.raises(RenderError, match=r"frames-per-process"):
        render.run(argparse.Namespace(**dict(vars(args), frames_per_process=-1)))
    assert not os.path.exists(tmp_path / "units")
