"""Renders named shapes from one viewpoint with the real renderer and lays them out as a PNG.

    /usr/bin/python3 blender_scripts/contact_sheet.py -o docs/images/basic_shapes.png \
        [--shapes configs/shapes/basic.json] [--direction X Y Z] [--resolution 256] [--columns 7]

Runs `blender ... -P blender_scripts/render.py` on a one-unit plan in a temporary directory
and colour-maps the label images (one hue per finger, darker towards the tip, shaded by depth).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from handdb_blender import exr, sheet, testplan  # noqa: E402
from handdb_blender.errors import RenderError  # noqa: E402
from handdb_blender.plan import REPO_ROOT, read_json  # noqa: E402

# Palm side, turned ~20 degrees towards the little finger and ~12 towards the fingertips: the
# handshapes as a viewer sees them, with the thumb in profile (not pointing at the camera).
DEFAULT_DIRECTION = (-0.9, -0.35, -0.2)


def shade(labels: np.ndarray, depth: np.ndarray) -> np.ndarray:
    rgb = sheet.colourise(labels).astype(np.float32)
    hand = labels > 0
    if hand.any():
        d = depth[hand]
        near, far = float(d.min()), float(d.max())
        t = np.zeros_like(depth)
        t[hand] = (depth[hand] - near) / max(far - near, 1e-6)
        rgb[hand] *= (1.0 - 0.45 * t[hand])[:, None]
    return rgb.astype(np.uint8)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--shapes", default=os.path.join(REPO_ROOT, "configs/shapes/basic.json"))
    p.add_argument("--direction", type=float, nargs=3, default=DEFAULT_DIRECTION)
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--columns", type=int, default=7)
    p.add_argument("--blender", default=shutil.which("blender") or "blender")
    args = p.parse_args()
    import cv2

    try:
        shapes = read_json(args.shapes, "shapes.schema.json")["shapes"]
        model = read_json(os.path.join(REPO_ROOT, testplan.HAND_MODEL), "hand_model.schema.json")
        plan = testplan.make_plan(shapes, [args.direction], unit_size=len(shapes), resolution=args.resolution,
                                  ortho_scale=model["ortho_scale"])
        with tempfile.TemporaryDirectory(prefix="handdb-sheet-") as tmp:
            plan_path = os.path.join(tmp, "plan.json")
            with open(plan_path, "w") as f:
                json.dump(plan, f)
            cmd = [args.blender, "-b", "--factory-startup", "-noaudio", "-t", "1", "-P",
                   os.path.join(REPO_ROOT, "blender_scripts", "render.py"), "--", "--plan", plan_path,
                   "--unit", "0", "--out", tmp]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RenderError((proc.stderr.strip().splitlines() or ["blender failed"])[-1])
            tiles, names = [], []
            for item in plan["units"][0]["renders"]:
                labels, depth = exr.read_labels_depth(
                    os.path.join(tmp, "units", "u00000", f"r{item['render_id']:06d}.exr"))
                tiles.append(shade(labels, depth))
                names.append(shapes[[s["id"] for s in shapes].index(item["shape_id"])]["name"])
        # Crop every tile to the union of the hands' boxes (same crop for all, so sizes compare).
        mask = np.any(np.stack([t != sheet.link_palette()[0] for t in tiles]).any(axis=3), axis=0)
        ys, xs = np.nonzero(mask)
        pad = args.resolution // 32
        y0, y1 = max(0, ys.min() - pad), min(args.resolution, ys.max() + 1 + pad)
        x0, x1 = max(0, xs.min() - pad), min(args.resolution, xs.max() + 1 + pad)
        if x1 - x0 < 150:  # room for the caption
            cx = (x0 + x1) // 2
            x0, x1 = max(0, cx - 75), min(args.resolution, cx + 75)
        img = sheet.contact_sheet([t[y0:y1, x0:x1] for t in tiles], names, args.columns)
        os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
        tmp_out = args.output + ".tmp.png"
        if not cv2.imwrite(tmp_out, img):
            raise RenderError(f"{args.output}: cannot write")
        os.replace(tmp_out, args.output)
    except (RenderError, exr.ExrError) as e:
        print(f"contact_sheet: {e}", file=sys.stderr)
        return 1
    print(f"wrote {args.output} ({len(tiles)} shapes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
