"""Renders one unit of a handdb plan headless (docs/conventions.md "Blender entry point").

    blender -b --factory-startup -noaudio -t 1 -P blender_scripts/render.py -- \
        --plan RUN_DIR/plan.json --unit 7 --out RUN_DIR [--frames-per-process N]

Per render item: units/uNNNNN/rNNNNNN.exr (multilayer half-float EXR: IndexMA.X = link id, Depth.Z) and
rNNNNNN.json (sidecar), each written to a temp name and renamed; items with both files are
skipped; units/uNNNNN/DONE is written last. Prints `rendered <render_id>` per finished item.
With --frames-per-process N the script re-executes Blender (same pid, fresh memory) after every
N renders until the unit is complete, capping leaks in long units.
Exit 0: unit complete. Exit 1: `handdb-render: <problem>` on stderr. Exit 2: bad usage.
"""

import argparse
import contextlib
import glob
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from handdb_blender import plan as planlib  # noqa: E402
from handdb_blender.errors import RenderError  # noqa: E402

RESTART = "restart"  # run() result: N renders done, items left -> re-exec Blender


def parse_args(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else []
    p = argparse.ArgumentParser(prog="render.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plan", required=True, help="plan.json written by `handdb plan`")
    p.add_argument("--unit", required=True, type=int, help="unit id to render")
    p.add_argument("--out", required=True, help="run directory (units/uNNNNN/ is created inside)")
    p.add_argument("--frames-per-process", type=int, default=0,
                   help="re-execute Blender after every N renders (fresh process, same pid; 0: never)")
    p.add_argument("--timing", action="store_true", help="print a timing line (setup/update/render) at the end")
    return p.parse_args(argv)


@contextlib.contextmanager
def quiet_stdout():
    """Blender's renderer prints progress lines on stdout; keep stdout for `rendered N`."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def run(args) -> int:
    t_start = time.perf_counter()
    plan_path = os.path.abspath(args.plan)
    plan = planlib.read_json(plan_path)
    planlib.check_plan(plan, plan_path)
    unit = planlib.find_unit(plan, args.unit, plan_path)
    # `handdb render` checks the whole plan against its schema before it starts. Here the schema
    # sees the plan with this unit's first item (Python's jsonschema needs seconds for a
    # 2,236-render plan, once per process); check_unit has checked every item of the unit.
    planlib.validate(dict(plan, units=[dict(unit, renders=unit["renders"][:1])]), "render_plan.schema.json",
                     plan_path)
    if args.frames_per_process < 0:
        raise RenderError(f"--frames-per-process must be >= 0, got {args.frames_per_process}")
    out_dir = os.path.abspath(args.out)
    udir = planlib.unit_dir(out_dir, unit["id"])
    done = planlib.done_path(out_dir, unit["id"])
    pending = planlib.pending_items(out_dir, unit)
    if not pending and os.path.exists(done):
        return 0
    model, model_path, asset_path = planlib.load_hand_model(plan, plan_path)
    model_sha = plan["hand_model"].get("sha256") or planlib.sha256_file(model_path)
    names = planlib.shape_names(plan)
    try:
        os.makedirs(udir, exist_ok=True)
    except OSError as e:
        raise RenderError(f"{udir}: cannot create: {e.strerror}") from None
    for stale in glob.glob(os.path.join(udir, "*.tmp")):  # left by a killed process
        os.remove(stale)

    import bpy  # noqa: F401  (only inside Blender)
    import numpy as np

    from handdb_blender import camera
    from handdb_blender.scene import CAMERA_DISTANCE, HandScene

    resolution = int(plan["render"]["resolution"])
    ortho_scale = float(plan["render"]["ortho_scale"])
    with quiet_stdout():
        hand = HandScene(model, asset_path, resolution, ortho_scale)
    blender_version = bpy.app.version_string
    look_at = np.asarray(model["look_at"])
    t_setup = time.perf_counter() - t_start
    t_update = t_render = 0.0
    count = 0
    last_joints = None
    for item in pending:
        if args.frames_per_process and count >= args.frames_per_process:
            break
        t0 = time.perf_counter()
        if last_joints != item["joints"]:  # shape-major plans: pose once per shape
            hand.set_pose(item["joints"])
            last_joints = item["joints"]
        roll = float(item.get("roll", 0.0))
        hand.set_camera(camera.blender_camera_matrix(item["direction"], model["forward_axis"], model["palm_normal"],
                                                     look_at, CAMERA_DISTANCE, roll))
        r = camera.cam_from_hand_rotation(item["direction"], model["forward_axis"], model["palm_normal"], roll)
        kp_cam, kp_px = camera.project(hand.keypoints_hand(), look_at, r, resolution, ortho_scale)
        theta, phi = camera.view_angles(item["direction"])
        side = planlib.sidecar(plan, unit, item, names.get(item["shape_id"], ""), kp_cam, kp_px, blender_version,
                               theta, phi, model_sha)
        exr_path, json_path = planlib.item_paths(out_dir, unit["id"], item["render_id"])
        t1 = time.perf_counter()
        with quiet_stdout():
            hand.render_to(exr_path + ".tmp")
        planlib.fsync_and_replace(exr_path + ".tmp", exr_path)
        planlib.write_json_atomic(json_path, side)
        t2 = time.perf_counter()
        t_update += t1 - t0
        t_render += t2 - t1
        count += 1
        print(f"rendered {item['render_id']}", flush=True)
    if args.timing:
        print(f"timing setup_s={t_setup:.3f} update_s={t_update:.3f} render_s={t_render:.3f} renders={count}",
              flush=True)
    if planlib.pending_items(out_dir, unit):
        if args.frames_per_process and count > 0:
            return RESTART
        raise RenderError(f"{udir}: items still missing after rendering")
    planlib.write_json_atomic(done, {"unit": unit["id"], "renders": len(unit["renders"]),
                                     "blender_version": blender_version, "script_version": planlib.SCRIPT_VERSION})
    return 0


def main() -> None:
    try:
        args = parse_args(sys.argv)
    except SystemExit as e:  # argparse: --help (0) or bad usage (2)
        sys.stdout.flush()
        os._exit(e.code if isinstance(e.code, int) else 2)
    try:
        code = run(args)
        if code == RESTART:
            import bpy

            sys.stdout.flush()
            sys.stderr.flush()
            os.execv(bpy.app.binary_path, [bpy.app.binary_path] + sys.argv[1:])
    except RenderError as e:
        print(f"handdb-render: {e}", file=sys.stderr, flush=True)
        code = 1
    except Exception as e:  # noqa: BLE001 - a one-line message instead of Blender carrying on
        print(f"handdb-render: internal error: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    sys.exit(code)


if __name__ == "__main__":
    main()
