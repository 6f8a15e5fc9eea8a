"""Renders one unit of a held-out test set (handdb testset; docs/evaluation.md).

    blender -b --factory-startup -noaudio -t 1 -P blender_scripts/render_testset.py -- \\
        --plan DIR/testset_plan.json --unit 3 --out DIR [--no-photos]

For every item of the unit: a label EXR + sidecar exactly like the database renders
(units/u00003/r000123.exr/.json, camera roll applied in Blender), then — with the scene switched to
a skin material, lights and a plain or procedurally cluttered background — a photo-like PNG
(photos/u00003/r000123.png), on the item's own background and shifted by its photo_offset_px when
it has them (test sequences). Items whose outputs exist are skipped; every file is written to a
temporary name and renamed; units/u00003/DONE and photos/u00003/DONE are written last. Errors:
one line `handdb-render: <message>` on stderr, exit status 1.
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from handdb_blender import camera, testset  # noqa: E402
from handdb_blender import plan as planlib  # noqa: E402
from handdb_blender.errors import RenderError  # noqa: E402


def parse_args(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else []
    p = argparse.ArgumentParser(prog="render_testset.py")
    p.add_argument("--plan", required=True, help="DIR/testset_plan.json")
    p.add_argument("--unit", type=int, required=True)
    p.add_argument("--out", required=True, help="the test-set directory")
    p.add_argument("--no-photos", action="store_true", help="label renders only")
    return p.parse_args(argv)


def render_atomic(hs, path: str) -> None:
    tmp = path + ".tmp"
    hs.render_to(tmp)
    planlib.fsync_and_replace(tmp, path)


def write_done(directory: str, count: int, blender_version: str) -> None:
    planlib.write_json_atomic(os.path.join(directory, "DONE"),
                              {"items": count, "blender_version": blender_version,
                               "script_version": "testset-" + testset.SCRIPT_VERSION})


def main() -> int:
    import bpy  # noqa: F401  (only inside Blender)
    from handdb_blender.photo import PhotoStudio
    from handdb_blender.scene import CAMERA_DISTANCE, HandScene

    args = parse_args(sys.argv)
    plan_path = os.path.abspath(args.plan)
    plan = testset.load_plan(plan_path)
    items = testset.unit_items(plan, args.unit)
    model, _, asset = planlib.load_hand_model(plan, plan_path)
    res = plan["render"]["resolution"]
    ortho = plan["render"]["ortho_scale"]
    fwd, palm, look_at = plan["forward_axis"], plan["palm_normal"], model["look_at"]
    blender_version = bpy.app.version_string

    unit_dir = os.path.join(args.out, "units", testset.unit_dir_name(args.unit))
    photo_dir = os.path.join(args.out, "photos", testset.unit_dir_name(args.unit))
    os.makedirs(unit_dir, exist_ok=True)
    os.makedirs(photo_dir, exist_ok=True)

    hs = HandScene(model, asset, res, ortho)

    def place(item):
        hs.set_pose(item["joints"])
        hs.set_camera(camera.blender_camera_matrix(item["direction"], fwd, palm, look_at,
                                                   CAMERA_DISTANCE, item["roll"]))

    # Label renders first (the scene as the database renders it), then one switch to photos.
    for item in items:
        exr = testset.label_path(args.out, args.unit, item["id"])
        side = testset.sidecar_path(args.out, args.unit, item["id"])
        if os.path.exists(exr) and os.path.exists(side):
            continue
        place(item)
        render_atomic(hs, exr)
        r = camera.cam_from_hand_rotation(item["direction"], fwd, palm, item["roll"])
        kp_cam, kp_px = camera.project(hs.keypoints_hand(), look_at, r, res, ortho)
        planlib.write_json_atomic(side, testset.make_sidecar(plan, item, kp_cam, kp_px, blender_version))
        print(f"rendered {item['id']}", flush=True)
    write_done(unit_dir, len(items), blender_version)

    if not args.no_photos:
        pending = [it for it in items
                   if not os.path.exists(testset.photo_path(args.out, args.unit, it["id"]))]
        if pending:
            studio = PhotoStudio(hs, plan["photo"], ortho, items)
            for item in pending:
                place(item)
                studio.set_item(item)
                render_atomic(hs, testset.photo_path(args.out, args.unit, item["id"]))
                print(f"photographed {item['id']}", flush=True)
        write_done(photo_dir, len(items), blender_version)
    return 0


if __name__ == "__main__":
    try:
        code = main()
    except RenderError as e:
        print(f"handdb-render: {e}", file=sys.stderr)
        code = 1
    except Exception as e:  # a Blender or script failure: still one clear line
        print(f"handdb-render: {type(e).__name__}: {e}", file=sys.stderr)
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
