#!/usr/bin/env python3
"""Python module benchmark: Python against C++ on the same database, in one run.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_bench.py --db DB [--build build]
        [--rounds 5] [--scan-reps 20] [--query-reps 3] [--threads 2] [--image PHOTO]...

1. Reading every view: C++ = build/bench/python_read_bench scan (manifest + every shard's
   ShardReader::Open + ScanViews, every point and label touched: docs/format.md's sequential
   scan over the database). Python = handdb.Database(DB) + db.read(start, stop) per shard (every
   label field as numpy columns, points zero-copy) + a numpy sum over every point; for
   comparison one db.read() of everything (points copied into one array) and the per-view loop
   (for v in db: v.points, v.joint_angles, v.keypoints).
   Target: Python >= 50 % of the C++ rate (views/s).
2. A query: C++ = Searcher::Search timed around the call (python_read_bench query); Python =
   db.search(...) on the same points (stored views rolled; --image photos too). What Python adds
   is measured in-process as (wall of the call - the search's own stats.seconds) minus the same
   difference in C++, relative to the C++ wall. Target: <= 5 %.

C++ and Python runs alternate round by round, so load changes on the shared machine hit both;
medians are printed. Needs the module on PYTHONPATH and a build with bench/.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

import handdb

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def cpp(build, *args):
    exe = os.path.join(build, "bench", "python_read_bench")
    r = subprocess.run([exe, *map(str, args)], capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def py_scan_columns(path):
    """Shard by shard: each db.read(start, stop) is zero-copy (points) plus the label columns."""
    t0, c0 = time.perf_counter(), time.process_time()
    db = handdb.Database(path)
    total = 0
    n = 0
    for start, stop in db.shard_ranges:
        cols = db.read(start, stop)
        total += int(cols["points"].sum(dtype=np.int64))
        total += int((cols["joint_angles"][:, 0] * 1000).astype(np.int64).sum())
        total += int(cols["render_id"].sum(dtype=np.int64))
        n += len(cols["render_id"])
    return time.perf_counter() - t0, time.process_time() - c0, n, total


def py_scan_all(path):
    """One db.read() of every view: the points of all shards copied into one array."""
    t0, c0 = time.perf_counter(), time.process_time()
    db = handdb.Database(path)
    cols = db.read()
    total = int(cols["points"].sum(dtype=np.int64)) + int((cols["joint_angles"][:, 0] * 1000).astype(np.int64).sum())
    total += int(cols["render_id"].sum(dtype=np.int64))
    return time.perf_counter() - t0, time.process_time() - c0, len(cols["render_id"]), total


def py_scan_views(path):
    t0, c0 = time.perf_counter(), time.process_time()
    db = handdb.Database(path)
    total = 0
    n = 0
    for v in db:
        total += int(v.points.sum(dtype=np.int64))
        v.joint_angles
        v.keypoints
        n += 1
    return time.perf_counter() - t0, time.process_time() - c0, n, total


def median(xs):
    return statistics.median(xs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--db", required=True)
    ap.add_argument("--build", default=os.path.join(REPO, "build"))
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--scan-reps", type=int, default=20)
    ap.add_argument("--query-reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--hand", default="either")
    ap.add_argument("--image", action="append", default=[])
    ap.add_argument("--json", help="also write the numbers here")
    args = ap.parse_args()

    db = handdb.Database(args.db)
    n = len(db)
    views = [(n * k // 4, (7 * k + 3) % db.num_rolls) for k in range(4)]
    print(f"database {args.db}: {n} views x {db.num_rolls} rolls, {db.num_points} points, "
          f"{db.size_bytes / 1e6:.1f} MB; load average {os.getloadavg()[0]:.1f}")

    # 1. Read every view.
    cpp_wall, cpp_cpu, col_wall, col_cpu, view_wall, view_cpu = [], [], [], [], [], []
    all_wall, all_cpu = [], []
    for _ in range(args.rounds):
        r = cpp(args.build, "scan", args.db, "--reps", args.scan_reps)
        cpp_wall.append(median(r["wall"]))
        cpp_cpu.append(median(r["cpu"]))
        assert r["views"] == n
        runs = [py_scan_columns(args.db) for _ in range(args.scan_reps)]
        assert runs[-1][3] == r["checksum"], "Python and C++ read different bytes"
        col_wall.append(median(x[0] for x in runs))
        col_cpu.append(median(x[1] for x in runs))
        runs = [py_scan_all(args.db) for _ in range(args.scan_reps)]
        assert runs[-1][3] == r["checksum"], "Python and C++ read different bytes"
        all_wall.append(median(x[0] for x in runs))
        all_cpu.append(median(x[1] for x in runs))
        runs = [py_scan_views(args.db) for _ in range(max(3, args.scan_reps // 4))]
        view_wall.append(median(x[0] for x in runs))
        view_cpu.append(median(x[1] for x in runs))
    scan = {
        "cpp_wall_s": median(cpp_wall), "cpp_cpu_s": median(cpp_cpu),
        "py_columns_wall_s": median(col_wall), "py_columns_cpu_s": median(col_cpu),
        "py_all_wall_s": median(all_wall), "py_all_cpu_s": median(all_cpu),
        "py_views_wall_s": median(view_wall), "py_views_cpu_s": median(view_cpu),
    }
    print("\nreading every view (open + every label and point), median of "
          f"{args.rounds} rounds x {args.scan_reps} reps:")
    print(f"  {'':38} {'wall ms':>9} {'views/s':>12} {'CPU ms':>9} {'vs C++ (wall / CPU)':>20}")
    for name, w, c in [("C++ ShardReader::ScanViews", scan["cpp_wall_s"], scan["cpp_cpu_s"]),
                       ("Python db.read(shard) + numpy sum", scan["py_columns_wall_s"], scan["py_columns_cpu_s"]),
                       ("Python db.read() (one copy) + sum", scan["py_all_wall_s"], scan["py_all_cpu_s"]),
                       ("Python for v in db (per-view objects)", scan["py_views_wall_s"], scan["py_views_cpu_s"])]:
        print(f"  {name:38} {w * 1e3:9.2f} {n / w:12,.0f} {c * 1e3:9.2f} "
              f"{100 * scan['cpp_wall_s'] / w:9.0f} % / {100 * scan['cpp_cpu_s'] / c:3.0f} %")
    for key in ["columns", "all", "views"]:
        scan[f"ratio_{key}_wall"] = scan["cpp_wall_s"] / scan[f"py_{key}_wall_s"]
        scan[f"ratio_{key}_cpu"] = scan["cpp_cpu_s"] / scan[f"py_{key}_cpu_s"]
    print(f"  target: Python >= 50 % of the C++ rate: db.read() shard by shard "
          f"{100 * scan['ratio_columns_wall']:.0f} % wall, {100 * scan['ratio_columns_cpu']:.0f} % CPU "
          f"({'met' if min(scan['ratio_columns_wall'], scan['ratio_columns_cpu']) >= 0.5 else 'MISSED'}); "
          f"one db.read() {100 * scan['ratio_all_wall']:.0f} %; per-view loop {100 * scan['ratio_views_wall']:.0f} %")

    # 2. Queries.
    cpp_args = ["query", args.db, "--reps", args.query_reps, "--threads", args.threads, "--hand", args.hand]
    for v, r in views:
        cpp_args += ["--view", v, "--roll", r]
    for image in args.image:
        cpp_args += ["--image", image]
    py_queries = [db[v].rolled(r)[0] for v, r in views] + list(args.image)
    names = [f"view {v} roll {r}" for v, r in views] + list(args.image)
    # The module builds its Searcher on the first search (the C++ side builds it before timing).
    db.search(py_queries[0], top_k=10, threads=args.threads, hand=args.hand)
    per_query = {name: {"cpp_wall": [], "cpp_inner": [], "py_wall": [], "py_inner": []} for name in names}
    for _ in range(args.rounds):
        for q in cpp(args.build, *cpp_args):
            per_query[q["query"]]["cpp_wall"] += q["wall"]
            per_query[q["query"]]["cpp_inner"] += q["search_seconds"]
        for name, query in zip(names, py_queries):
            if isinstance(query, str):
                # The image's edges once, outside the timing (the C++ side loads them outside too).
                query = handdb.query_edges(query, database=db)
            for _ in range(args.query_reps):
                t0 = time.perf_counter()
                _, stats = db.search(query, top_k=10, threads=args.threads, hand=args.hand, return_stats=True)
                per_query[name]["py_wall"].append(time.perf_counter() - t0)
                per_query[name]["py_inner"].append(stats["seconds"])
    print(f"\nqueries (top 10, --hand {args.hand}, {args.threads} threads), median of "
          f"{args.rounds} rounds x {args.query_reps} reps:")
    print(f"  {'query':28} {'C++ ms':>9} {'Python ms':>10} {'ratio':>7} {'Python adds (in-process)':>26}")
    added = []
    rows = {}
    for name in names:
        d = per_query[name]
        cw, pw = median(d["cpp_wall"]), median(d["py_wall"])
        cpp_extra = median(w - i for w, i in zip(d["cpp_wall"], d["cpp_inner"]))
        py_extra = median(w - i for w, i in zip(d["py_wall"], d["py_inner"]))
        add = (py_extra - cpp_extra) / cw
        added.append(add)
        rows[name] = {"cpp_wall_s": cw, "py_wall_s": pw, "py_added_s": py_extra - cpp_extra, "py_added": add}
        print(f"  {os.path.basename(name)[:28]:28} {cw * 1e3:9.1f} {pw * 1e3:10.1f} {pw / cw:7.3f} "
              f"{(py_extra - cpp_extra) * 1e6:12.0f} us = {100 * add:6.3f} %")
    worst = max(added)
    print(f"  target: a Python query adds <= 5 % to the C++ query: worst {100 * worst:.3f} % "
          f"({'met' if worst <= 0.05 else 'MISSED'})")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"scan": scan, "queries": rows, "load_average": os.getloadavg()[0]}, f, indent=2)


if __name__ == "__main__":
    sys.exit(main())
