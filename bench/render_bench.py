#!/usr/bin/python3
"""Rendering throughput of blender_scripts/render.py: renders/s for S shapes x D directions at
R px with J parallel Blender processes (default: the paper's 26 x 86 at 256 px, 2 jobs; target
>= 15 renders/s on a 2-core machine), and the per-render split between Blender start-up, scene
update (pose + camera + keypoints + sidecar) and Cycles render + EXR write.

    /usr/bin/python3 bench/render_bench.py [--shapes 26] [--dirs 86] [--resolution 256]
        [--jobs 2] [--unit-size 172] [--out DIR] [--json]

Baseline measured in the same run: one bare Blender start (`-b --factory-startup`, empty
script), so start-up cost per render = bare start / unit size.
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "blender_scripts"))

from handdb_blender import testplan  # noqa: E402

RENDER_PY = os.path.join(REPO, "blender_scripts", "render.py")


def blender_cmd(blender, *script_args):
    return [blender, "-b", "--factory-startup", "-noaudio", "-t", "1", *script_args]


def bare_start(blender, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run(blender_cmd(blender, "--python-expr", "pass"), capture_output=True, check=True)
        best = min(best, time.perf_counter() - t)
    return best


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--shapes", type=int, default=26)
    p.add_argument("--dirs", type=int, default=86)
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--unit-size", type=int, default=172)
    p.add_argument("--out", help="run directory (default: a temporary one, removed)")
    p.add_argument("--blender", default=shutil.which("blender") or "blender")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = p.parse_args()

    shapes = testplan.basic_shapes()
    shapes = [shapes[i % len(shapes)] | {"id": i} for i in range(args.shapes)]
    plan = testplan.make_plan(shapes, testplan.fibonacci_directions(args.dirs), args.unit_size,
                              resolution=args.resolution)
    out = args.out or tempfile.mkdtemp(prefix="handdb-render-bench-")
    os.makedirs(out, exist_ok=True)
    plan_path = os.path.join(out, "plan.json")
    with open(plan_path, "w") as f:
        json.dump(plan, f)

    start_s = bare_start(args.blender)
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    queue = [u["id"] for u in plan["units"]]
    running = {}
    per_unit = []
    t0 = time.perf_counter()
    while queue or running:
        while queue and len(running) < args.jobs:
            unit = queue.pop(0)
            cmd = blender_cmd(args.blender, "-P", RENDER_PY, "--", "--plan", plan_path, "--unit", str(unit),
                              "--out", out, "--timing")
            running[unit] = (subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
                             time.perf_counter())
        for unit, (proc, started) in list(running.items()):
            if proc.poll() is None:
                continue
            stdout, stderr = proc.communicate()
            wall = time.perf_counter() - started
            del running[unit]
            if proc.returncode != 0:
                sys.exit(f"render_bench: unit {unit} failed ({proc.returncode}): {stderr.strip()[-300:]}")
            line = [x for x in stdout.splitlines() if x.startswith("timing ")][-1]
            t = {k: float(v) for k, v in (kv.split("=") for kv in line.split()[1:])}
            t["wall_s"] = wall
            per_unit.append(t)
        time.sleep(0.02)
    total_s = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    renders = sum(int(t["renders"]) for t in per_unit)
    cpu_sum = {k: sum(t[k] for t in per_unit) for k in ("setup_s", "update_s", "render_s", "wall_s")}
    # Start-up = process wall time not spent in our script's setup, update and render loop.
    startup = cpu_sum["wall_s"] - cpu_sum["setup_s"] - cpu_sum["update_s"] - cpu_sum["render_s"]
    result = {
        "shapes": args.shapes, "directions": args.dirs, "resolution": args.resolution, "jobs": args.jobs,
        "unit_size": args.unit_size, "renders": renders, "seconds": round(total_s, 2),
        "renders_per_s": round(renders / total_s, 2), "target_renders_per_s": 15.0,
        "ratio_to_target": round(renders / total_s / 15.0, 2),
        "bare_blender_start_s": round(start_s, 3),
        "per_render_ms": {
            "blender_start": round(1e3 * startup / renders, 2),
            "scene_setup": round(1e3 * cpu_sum["setup_s"] / renders, 2),
            "scene_update": round(1e3 * cpu_sum["update_s"] / renders, 2),
            "cycles_render_and_write": round(1e3 * cpu_sum["render_s"] / renders, 2),
        },
        "cpu_s": round(cpu_s, 2),
        "cpu_ms_per_render": round(1e3 * cpu_s / renders, 2),
        # What J busy cores would give if nothing else ran: renders / (CPU time / J).
        "cpu_bound_renders_per_s": round(renders / (cpu_s / args.jobs), 1),
        "load_average": os.getloadavg()[0],
    }
    if not args.out:
        shutil.rmtree(out, ignore_errors=True)
    if args.json:
        print(json.dumps(result))
        return
    print(f"render_bench: {renders} renders ({args.shapes} shapes x {args.dirs} directions, {args.resolution} px), "
          f"{args.jobs} jobs, units of {args.unit_size}")
    print(f"  total {total_s:.1f} s -> {renders / total_s:.1f} renders/s (target 15/s: x{renders / total_s / 15:.2f})")
    print(f"  bare Blender start-up (baseline, same run): {start_s:.2f} s")
    pr = result["per_render_ms"]
    print(f"  per render (process time, summed over jobs): start-up {pr['blender_start']:.1f} ms, scene setup "
          f"{pr['scene_setup']:.1f} ms, update {pr['scene_update']:.1f} ms, Cycles+EXR {pr['cycles_render_and_write']:.1f} ms")
    print(f"  CPU time {cpu_s:.1f} s = {1e3 * cpu_s / renders:.1f} ms/render -> {result['cpu_bound_renders_per_s']:.0f} "
          f"renders/s if {args.jobs} cores were free (wall-clock above is what this run got)")
    print(f"  load average at the end: {result['load_average']:.2f} (other work on the machine slows this)")


if __name__ == "__main__":
    main()
