"""Builds small plans by hand (tests, the contact sheet, the benchmark) in the layout of
docs/conventions.md "Plan JSON", so the renderer can run before or without `handdb plan`."""

from __future__ import annotations

import math
import os
from typing import List, Sequence

from . import plan as planlib

HAND_MODEL = "configs/hands/webxr_generic_right.json"
BASIC_SHAPES = "configs/shapes/basic.json"


def fibonacci_directions(n: int) -> List[List[float]]:
    out = []
    golden = math.pi * (3.0 - math.sqrt(5.0))
    for i in range(n):
        z = 1.0 - (2.0 * i + 1.0) / n
        r = math.sqrt(max(0.0, 1.0 - z * z))
        out.append([r * math.cos(golden * i), r * math.sin(golden * i), z])
    return out


def make_plan(shapes: Sequence[dict], directions: Sequence[Sequence[float]], unit_size: int,
              resolution: int = 256, ortho_scale: float = 0.3, rolls: Sequence[float] = (0.0,),
              hand_model: str = HAND_MODEL) -> dict:
    """Shape-major items (render_id = (shape_index * ndirs + dir) * nrolls + roll_index)."""
    model_path = os.path.join(planlib.REPO_ROOT, hand_model)
    dirs = []
    for i, d in enumerate(directions):
        n = math.sqrt(sum(x * x for x in d))
        d = [x / n for x in d]
        dirs.append({"id": i, "direction": d, "theta": math.acos(max(-1.0, min(1.0, d[2]))),
                     "phi": math.atan2(d[1], d[0])})
    items = []
    for s in shapes:
        for d in dirs:
            for roll in rolls:
                items.append({"render_id": len(items), "shape_id": s["id"], "dir_id": d["id"],
                              "joints": list(s["joints"]), "direction": d["direction"], "roll": roll})
    units = [{"id": u, "renders": items[k:k + unit_size]} for u, k in enumerate(range(0, len(items), unit_size))]
    return {
        "format": "handdb-plan", "version": 1, "seed": 1,
        "config": {"note": "hand-made test plan (blender_scripts/handdb_blender/testplan.py)"},
        "hand_model": {"path": model_path, "sha256": planlib.sha256_file(model_path)},
        "render": {"resolution": resolution, "ortho_scale": ortho_scale, "engine": "cycles"},
        "rolls": 1,
        "unit_size": unit_size,
        "shapes": [{"id": s["id"], "name": s["name"], "joints": list(s["joints"]), "coeffs": []} for s in shapes],
        "directions": dirs,
        "units": units,
    }


def basic_shapes() -> List[dict]:
    return planlib.read_json(os.path.join(planlib.REPO_ROOT, BASIC_SHAPES), "shapes.schema.json")["shapes"]
