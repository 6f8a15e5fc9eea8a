"""Plan parsing, validation and output layout for the Blender renderer (no bpy).

The plan layout is docs/conventions.md "Plan JSON"; the output layout is "Files and directories".
Every problem with outside input raises RenderError with one line naming the file.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from typing import Dict, List, Optional, Sequence

from .errors import RenderError

SCRIPT_VERSION = "1"
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCHEMA_DIR = os.path.join(REPO_ROOT, "schemas")


def sha256_file(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def read_json(path: str, schema_name: Optional[str] = None) -> dict:
    """Parses a JSON file and checks it against schemas/<schema_name> when that schema exists."""
    try:
        with open(path, "r", encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise RenderError(f"{path}: file not found") from None
    except OSError as e:
        raise RenderError(f"{path}: cannot read: {e.strerror}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise RenderError(f"{path}: line {e.lineno}, column {e.colno}: {e.msg}") from None
    except UnicodeDecodeError as e:
        raise RenderError(f"{path}: not UTF-8 text: {e.reason}") from None
    if schema_name:
        validate(doc, schema_name, path)
    return doc


def validate(doc, schema_name: str, what: str) -> None:
    schema_path = os.path.join(SCHEMA_DIR, schema_name)
    if not os.path.exists(schema_path):
        return  # the schema lands with its module; the semantic checks below still run
    import jsonschema  # Debian python3-jsonschema, also visible to Debian's Blender

    with open(schema_path, "r", encoding="utf-8") as f:
        schema = json.load(f)
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(doc), key=lambda e: list(e.absolute_path))
    if errors:
        e = errors[0]
        pointer = "/" + "/".join(str(p) for p in e.absolute_path)
        raise RenderError(f"{what}: {pointer}: {e.message}")


def _finite_vector(v, n: int, what: str) -> List[float]:
    if not isinstance(v, list) or len(v) != n or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise RenderError(f"{what}: expected {n} numbers, got {json.dumps(v)[:80]}")
    if not all(math.isfinite(x) for x in v):
        raise RenderError(f"{what}: non-finite value in {v}")
    return [float(x) for x in v]


def check_plan(plan: dict, path: str) -> None:
    """Semantic checks the renderer relies on (beyond the schema)."""
    if not isinstance(plan, dict):
        raise RenderError(f"{path}: top level is not an object")
    if plan.get("format") != "handdb-plan":
        raise RenderError(f"{path}: /format: expected \"handdb-plan\", got {json.dumps(plan.get('format'))}")
    if plan.get("version") != 1:
        raise RenderError(f"{path}: /version: unsupported plan version {json.dumps(plan.get('version'))}")
    render = plan.get("render")
    if not isinstance(render, dict):
        raise RenderError(f"{path}: /render: missing")
    res = render.get("resolution")
    if not isinstance(res, int) or isinstance(res, bool) or not 8 <= res <= 8192:
        raise RenderError(f"{path}: /render/resolution: expected an integer in 8..8192, got {json.dumps(res)}")
    scale = render.get("ortho_scale")
    if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not (math.isfinite(scale) and scale > 0):
        raise RenderError(f"{path}: /render/ortho_scale: expected a positive number, got {json.dumps(scale)}")
    engine = render.get("engine", "cycles")
    if str(engine).lower() != "cycles":
        raise RenderError(f"{path}: /render/engine: only \"cycles\" is supported, got {json.dumps(engine)}")
    hm = plan.get("hand_model")
    if not isinstance(hm, dict) or not isinstance(hm.get("path"), str) or not hm["path"]:
        raise RenderError(f"{path}: /hand_model/path: missing")
    if not isinstance(plan.get("units"), list):
        raise RenderError(f"{path}: /units: missing")
    if not isinstance(plan.get("shapes"), list):
        raise RenderError(f"{path}: /shapes: missing")


def find_unit(plan: dict, unit_id: int, path: str) -> dict:
    for i, unit in enumerate(plan["units"]):
        if isinstance(unit, dict) and unit.get("id") == unit_id:
            check_unit(unit, f"{path}: /units/{i}")
            return unit
    raise RenderError(f"{path}: no unit with id {unit_id} (plan has {len(plan['units'])} units)")


def check_unit(unit: dict, where: str) -> None:
    renders = unit.get("renders")
    if not isinstance(renders, list) or not renders:
        raise RenderError(f"{where}/renders: expected a non-empty list")
    seen = set()
    for k, item in enumerate(renders):
        w = f"{where}/renders/{k}"
        if not isinstance(item, dict):
            raise RenderError(f"{w}: not an object")
        for key in ("render_id", "shape_id", "dir_id"):
            v = item.get(key)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise RenderError(f"{w}/{key}: expected a non-negative integer, got {json.dumps(v)}")
        if item["render_id"] in seen:
            raise RenderError(f"{w}/render_id: duplicate {item['render_id']}")
        seen.add(item["render_id"])
        _finite_vector(item.get("joints"), 20, f"{w}/joints")
        d = _finite_vector(item.get("direction"), 3, f"{w}/direction")
        if abs(math.sqrt(sum(x * x for x in d)) - 1.0) > 1e-3:
            raise RenderError(f"{w}/direction: not a unit vector: {d}")
        roll = item.get("roll", 0.0)
        if not isinstance(roll, (int, float)) or isinstance(roll, bool) or not math.isfinite(roll):
            raise RenderError(f"{w}/roll: expected a finite number, got {json.dumps(roll)}")


def resolve_path(p: str, bases: Sequence[str]) -> Optional[str]:
    if os.path.isabs(p):
        return p if os.path.exists(p) else None
    for base in bases:
        c = os.path.join(base, p)
        if os.path.exists(c):
            return os.path.abspath(c)
    return None


def load_hand_model(plan: dict, plan_path: str) -> tuple:
    """(model dict, model path, asset path). Relative paths are tried against the plan's
    directory, the working directory and the repository root; hashes must match."""
    hm = plan["hand_model"]
    bases = [os.path.dirname(os.path.abspath(plan_path)), os.getcwd(), REPO_ROOT]
    model_path = resolve_path(hm["path"], bases)
    if model_path is None:
        raise RenderError(f"{plan_path}: hand model '{hm['path']}' not found")
    want = hm.get("sha256")
    if want and sha256_file(model_path) != want:
        raise RenderError(f"{model_path}: sha256 differs from the plan's hand_model.sha256")
    model = read_json(model_path, "hand_model.schema.json")
    check_hand_model(model, model_path)
    asset = model["asset"]
    asset_path = resolve_path(asset["path"], [os.path.dirname(model_path), os.path.dirname(os.path.dirname(model_path)),
                                              os.path.dirname(os.path.dirname(os.path.dirname(model_path))), REPO_ROOT])
    if asset_path is None:
        raise RenderError(f"{model_path}: hand asset '{asset['path']}' not found (run scripts/deps.sh)")
    if sha256_file(asset_path) != asset["sha256"]:
        raise RenderError(f"{asset_path}: sha256 differs from the hand model's asset.sha256")
    return model, model_path, asset_path


def check_hand_model(model: dict, path: str) -> None:
    bones = {b["name"]: b for b in model["bones"]}
    for b in model["bones"]:
        if b["parent"] is not None and b["parent"] not in bones:
            raise RenderError(f"{path}: bone '{b['name']}' has unknown parent '{b['parent']}'")
    if sorted(d["index"] for d in model["dofs"]) != list(range(20)):
        raise RenderError(f"{path}: /dofs: indices must be 0..19 once each")
    for d in model["dofs"]:
        if d["bone"] not in bones:
            raise RenderError(f"{path}: DOF '{d['name']}' names unknown bone '{d['bone']}'")
        if not d["min"] <= d["max"]:
            raise RenderError(f"{path}: DOF '{d['name']}' has min > max")
    if sorted(k["index"] for k in model["keypoints"]) != list(range(21)):
        raise RenderError(f"{path}: /keypoints: indices must be 0..20 once each")
    for k in model["keypoints"]:
        if k["bone"] not in bones:
            raise RenderError(f"{path}: keypoint '{k['name']}' names unknown bone '{k['bone']}'")
    if sorted(link["id"] for link in model["links"]) != list(range(1, 17)):
        raise RenderError(f"{path}: /links: ids must be 1..16 once each")


def unit_dir(out_dir: str, unit_id: int) -> str:
    return os.path.join(out_dir, "units", f"u{unit_id:05d}")


def item_paths(out_dir: str, unit_id: int, render_id: int) -> tuple:
    base = os.path.join(unit_dir(out_dir, unit_id), f"r{render_id:06d}")
    return base + ".exr", base + ".json"


def done_path(out_dir: str, unit_id: int) -> str:
    return os.path.join(unit_dir(out_dir, unit_id), "DONE")


def pending_items(out_dir: str, unit: dict) -> List[dict]:
    out = []
    for item in unit["renders"]:
        exr, side = item_paths(out_dir, unit["id"], item["render_id"])
        if not (os.path.exists(exr) and os.path.exists(side)):
            out.append(item)
    return out


def shape_names(plan: dict) -> Dict[int, str]:
    return {s["id"]: s.get("name", "") for s in plan["shapes"] if isinstance(s, dict) and "id" in s}


def sidecar(plan: dict, unit: dict, item: dict, shape_name: str, kp_cam, kp_px, blender_version: str,
            view_theta: float, view_phi: float, hand_model_sha256: str) -> dict:
    r = plan["render"]
    return {
        "render_id": item["render_id"],
        "unit": unit["id"],
        "shape_id": item["shape_id"],
        "shape_name": shape_name,
        "dir_id": item["dir_id"],
        "joint_angles": [float(x) for x in item["joints"]],
        "view_direction": [float(x) for x in item["direction"]],
        "view_theta": float(view_theta),
        "view_phi": float(view_phi),
        "camera_roll": float(item.get("roll", 0.0)),
        "resolution": int(r["resolution"]),
        "ortho_scale": float(r["ortho_scale"]),
        "keypoints_cam": [[float(v) for v in p] for p in kp_cam],
        "keypoints_px": [[float(v) for v in p] for p in kp_px],
        "blender_version": blender_version,
        "script_version": SCRIPT_VERSION,
        "hand_model_sha256": hand_model_sha256,
    }


def write_atomic(path: str, data: bytes) -> None:
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_json_atomic(path: str, doc) -> None:
    write_atomic(path, (json.dumps(doc) + "\n").encode())


def fsync_and_replace(tmp: str, path: str) -> None:
    with open(tmp, "rb+") as f:
        os.fsync(f.fileno())
    os.replace(tmp, path)
