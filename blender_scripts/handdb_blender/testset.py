"""Test-set plans (schemas/testset_plan.schema.json) on the Blender side, without bpy.

`handdb testset` writes DIR/testset_plan.json; blender_scripts/render_testset.py renders one unit
of it: a label EXR + sidecar per item (the database's render layout, so the C++ converter reads
them) and a photo-like PNG. This module holds the parts that need no Blender: reading and checking
the plan, file names, sidecar documents, and the seeded parameters of the cluttered backgrounds.
"""

from __future__ import annotations

import colorsys
import math
import os
import random
from typing import Dict, List, Sequence

from . import plan as planlib
from .errors import RenderError

SCRIPT_VERSION = "1"
FORMAT = "handdb-testset-plan"

_ITEM_KEYS = ("id", "unit", "seed", "basic", "shape_name", "joints", "coeffs", "clamped",
              "direction", "theta", "phi", "roll")


def load_plan(path: str) -> dict:
    """Reads a test-set plan: schema check (schemas/testset_plan.schema.json) and the order of
    items and units the renderer relies on."""
    plan = planlib.read_json(path, "testset_plan.schema.json")
    if not isinstance(plan, dict) or plan.get("format") != FORMAT or plan.get("version") != 1:
        raise RenderError(f"{path}: not a version-1 {FORMAT} file")
    for key in ("hand_model", "render", "photo", "unit_size", "items", "forward_axis", "palm_normal"):
        if key not in plan:
            raise RenderError(f"{path}: missing '{key}'")
    unit_size = plan["unit_size"]
    if not isinstance(unit_size, int) or unit_size < 1:
        raise RenderError(f"{path}: unit_size must be a positive integer, got {unit_size!r}")
    for i, item in enumerate(plan["items"]):
        missing = [k for k in _ITEM_KEYS if k not in item]
        if missing:
            raise RenderError(f"{path}: item {i}: missing {', '.join(missing)}")
        if item["id"] != i or item["unit"] != i // unit_size:
            raise RenderError(f"{path}: item {i}: id {item['id']} / unit {item['unit']} out of order")
        if len(item["joints"]) != 20:
            raise RenderError(f"{path}: item {i}: {len(item['joints'])} joint angles, expected 20")
    return plan


def num_units(plan: dict) -> int:
    return (len(plan["items"]) + plan["unit_size"] - 1) // plan["unit_size"]


def unit_items(plan: dict, unit: int) -> List[dict]:
    if unit < 0 or unit >= num_units(plan):
        raise RenderError(f"unit {unit} is not in the plan (it has {num_units(plan)} units)")
    size = plan["unit_size"]
    return plan["items"][unit * size:(unit + 1) * size]


def unit_dir_name(unit: int) -> str:
    return f"u{unit:05d}"


def render_stem(item_id: int) -> str:
    return f"r{item_id:06d}"


def label_path(out: str, unit: int, item_id: int) -> str:
    return os.path.join(out, "units", unit_dir_name(unit), render_stem(item_id) + ".exr")


def sidecar_path(out: str, unit: int, item_id: int) -> str:
    return os.path.join(out, "units", unit_dir_name(unit), render_stem(item_id) + ".json")


def photo_path(out: str, unit: int, item_id: int) -> str:
    return os.path.join(out, "photos", unit_dir_name(unit), render_stem(item_id) + ".png")


def render_item(item: dict) -> dict:
    """A test item in the shape of a plan's render item: render, shape and direction ids are all
    the item id (a test set has no shape x direction grid); the roll is rendered, not virtual."""
    return {"render_id": item["id"], "shape_id": item["id"], "dir_id": item["id"],
            "joints": item["joints"], "direction": item["direction"], "roll": item["roll"]}


def make_sidecar(plan: dict, item: dict, keypoints_cam, keypoints_px, blender_version: str) -> dict:
    """The render sidecar of docs/conventions.md (the database renderer's own builder)."""
    return planlib.sidecar(plan, {"id": item["unit"]}, render_item(item), item["shape_name"],
                           keypoints_cam, keypoints_px, blender_version, float(item["theta"]),
                           float(item["phi"]), plan["hand_model"]["sha256"])


def uses_forearm(photo: dict) -> bool:
    """Whether any photo of the plan shows a forearm: all (`forearm`) or those items whose entry
    says so (`forearm_fraction`)."""
    return bool(photo.get("forearm", False)) or "forearm_fraction" in photo


def item_forearm(item: dict, default: bool) -> bool:
    """Whether this item's photo shows the forearm: its own entry, else the plan's `forearm`."""
    return bool(item.get("forearm", default))


def item_clutter(item: dict, default: bool) -> bool:
    """Whether this item's photo has the cluttered background: its own entry, else the plan's."""
    return bool(item.get("clutter", default))


def item_offset_px(item: dict) -> List[float]:
    """The hand's shift in this item's photo, px (x right, y down); [0, 0] when the plan has none."""
    offset = item.get("photo_offset_px", [0.0, 0.0])
    if len(offset) != 2:
        raise RenderError(f"item {item.get('id')}: photo_offset_px must be 2 numbers, got {offset!r}")
    return [float(offset[0]), float(offset[1])]


def srgb_to_linear(c: float) -> float:
    """Blender colour inputs are scene-linear; configs give sRGB."""
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def clutter_params(seed: int) -> Dict[str, object]:
    """Seeded parameters of one cluttered background: a Voronoi cell pattern, a noise layer and
    stripes, with colours of random hue (some near skin hues, as in real clutter). The same seed
    always gives the same background."""
    rng = random.Random(seed)

    def colour(sat_lo: float, sat_hi: float, val_lo: float, val_hi: float) -> List[float]:
        h = rng.random()
        s = rng.uniform(sat_lo, sat_hi)
        v = rng.uniform(val_lo, val_hi)
        return [srgb_to_linear(c) for c in colorsys.hsv_to_rgb(h, s, v)]

    return {
        "offset": [rng.uniform(-50, 50) for _ in range(3)],
        "rotation": rng.uniform(0, 2 * math.pi),
        "cell_scale": rng.uniform(3.0, 12.0),
        "noise_scale": rng.uniform(2.0, 15.0),
        "noise_detail": rng.uniform(1.0, 8.0),
        "wave_scale": rng.uniform(1.0, 6.0),
        "mix_noise": rng.uniform(0.2, 0.6),
        "mix_wave": rng.uniform(0.0, 0.5),
        "colours": [colour(0.1, 0.8, 0.15, 0.95) for _ in range(4)],
        "brightness": rng.uniform(0.6, 1.1),
    }


def light_params(seed: int) -> Dict[str, float]:
    """Key light direction relative to the camera (degrees) and strengths; mildly varied per item
    so the photos do not all share one shading."""
    rng = random.Random(seed ^ 0x11647)
    return {
        "key_pitch_deg": rng.uniform(20.0, 45.0),
        "key_yaw_deg": rng.uniform(-35.0, 35.0),
        "key_strength": rng.uniform(2.5, 4.0),
        "fill_strength": rng.uniform(0.6, 1.2),
        "ambient": rng.uniform(0.15, 0.35),
    }


def check_rgb(values: Sequence[float], what: str) -> List[float]:
    if len(values) != 3 or any(not (0.0 <= float(v) <= 1.0) for v in values):
        raise RenderError(f"{what} must be 3 numbers in 0..1, got {list(values)}")
    return [float(v) for v in values]
