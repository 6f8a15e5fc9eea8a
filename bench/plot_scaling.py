#!/usr/bin/python3
"""Latency against database size, from index_bench outputs (the scaling plot of bench/run.sh).

Usage: bench/plot_scaling.py [--candidates N] OUT.png INDEX_BENCH_OUTPUT.txt [...]

Each input is the stdout of one `index_bench` run on one database. The plot has the number of
virtual views on a log x axis and the median search latency (ms, wall, 2 threads as run) on a
log y axis: one line per query set for exact search (solid) and one for indexed search (dashed) at
--candidates N per hand (default: the smallest candidate count of each run). Drawn with OpenCV
(Debian's python3-opencv), so it needs nothing from PyPI. The numbers it read are printed as a
table as well.
"""
import math
import os
import re
import sys

import cv2
import numpy as np

SETS = ["photos", "testset-photo", "testset-clean", "perturbed"]
COLOURS = {  # BGR
    "photos": (40, 40, 200),
    "testset-photo": (40, 140, 40),
    "testset-clean": (200, 110, 30),
    "perturbed": (110, 110, 110),
}


def parse(path, candidates=None):
    """{'views': N, 'exact': {set: ms}, 'indexed': {set: ms}, 'candidates': C}: the indexed line
    of `candidates` per hand, or the first (smallest) when None."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    m = re.search(r"= (\d+) virtual views", text)
    if not m:
        sys.exit(f"{path}: no 'N virtual views' line: not an index_bench output")
    out = {"views": int(m.group(1)), "exact": {}, "indexed": {}, "candidates": None}
    current = None
    for line in text.splitlines():
        head = re.match(r"^([\w-]+): ", line)
        if head and head.group(1) in SETS:
            current = head.group(1)
            continue
        if current is None:
            continue
        m = re.match(r"^\s+exact\s+median\s+([\d.]+) ms", line)
        if m:
            out["exact"][current] = float(m.group(1))
            continue
        m = re.match(r"^\s+indexed C=(\d+)\s+median\s+([\d.]+) ms", line)
        if m and current not in out["indexed"] and candidates in (None, int(m.group(1))):
            out["indexed"][current] = float(m.group(2))
            out["candidates"] = int(m.group(1))
    if not out["exact"] and not out["indexed"]:
        sys.exit(f"{path}: no latency lines found")
    return out


def main():
    argv = sys.argv[1:]
    candidates = None
    if argv[:1] == ["--candidates"] and len(argv) >= 2:
        candidates = int(argv[1])
        argv = argv[2:]
    if len(argv) < 2:
        sys.exit(__doc__)
    sys.argv = [sys.argv[0]] + argv
    runs = sorted((parse(p, candidates) for p in argv[1:]), key=lambda r: r["views"])
    print(f"{'virtual views':>14} {'set':<14} {'exact ms':>9} {'indexed ms':>11}")
    for r in runs:
        for s in SETS:
            e, i = r["exact"].get(s), r["indexed"].get(s)
            if e is None and i is None:
                continue
            print(f"{r['views']:>14,} {s:<14} {e if e is not None else '-':>9} "
                  f"{i if i is not None else '-':>11}")

    width, height, left, right, top, bottom = 960, 600, 90, 250, 40, 70
    img = np.full((height, width, 3), 255, np.uint8)
    xs = [math.log10(r["views"]) for r in runs]
    values = [v for r in runs for k in ("exact", "indexed") for v in r[k].values()]
    x0, x1 = math.floor(min(xs) - 0.1), math.ceil(max(xs) + 0.1)
    y0, y1 = math.floor(math.log10(min(values))), math.ceil(math.log10(max(values)))

    def px(logx, logy):
        u = left + (logx - x0) / (x1 - x0) * (width - left - right)
        v = height - bottom - (logy - y0) / (y1 - y0) * (height - top - bottom)
        return int(round(u)), int(round(v))

    font = cv2.FONT_HERSHEY_SIMPLEX
    for e in range(x0, x1 + 1):  # decades and their labels
        a, b = px(e, y0), px(e, y1)
        cv2.line(img, a, b, (225, 225, 225), 1)
        label = f"{10 ** e:,}" if e < 6 else f"{10 ** (e - 6):,}M"
        cv2.putText(img, label, (a[0] - 20, a[1] + 22), font, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    for e in range(y0, y1 + 1):
        a, b = px(x0, e), px(x1, e)
        cv2.line(img, a, b, (225, 225, 225), 1)
        cv2.putText(img, f"{10 ** e:g}", (a[0] - 60, a[1] + 5), font, 0.5, (0, 0, 0), 1,
                    cv2.LINE_AA)
    cv2.rectangle(img, px(x0, y1), px(x1, y0), (0, 0, 0), 1)
    cv2.putText(img, "virtual views (log)", (left + 250, height - 20), font, 0.6, (0, 0, 0), 1,
                cv2.LINE_AA)
    cv2.putText(img, "median search latency, ms (log), 2 threads, top 10, --hand either",
                (left, 25), font, 0.55, (0, 0, 0), 1, cv2.LINE_AA)

    legend_y = top + 10
    candidates = next((r["candidates"] for r in runs if r["candidates"]), None)
    for s in SETS:
        for kind, dashed in (("exact", False), ("indexed", True)):
            pts = [px(math.log10(r["views"]), math.log10(r[kind][s])) for r in runs
                   if s in r[kind]]
            if not pts:
                continue
            for a, b in zip(pts, pts[1:]):
                if dashed:
                    n = max(1, int(math.dist(a, b) // 12))
                    for k in range(0, n, 2):
                        p = (int(a[0] + (b[0] - a[0]) * k / n), int(a[1] + (b[1] - a[1]) * k / n))
                        q = (int(a[0] + (b[0] - a[0]) * (k + 1) / n),
                             int(a[1] + (b[1] - a[1]) * (k + 1) / n))
                        cv2.line(img, p, q, COLOURS[s], 2, cv2.LINE_AA)
                else:
                    cv2.line(img, a, b, COLOURS[s], 2, cv2.LINE_AA)
            for p in pts:
                cv2.circle(img, p, 4, COLOURS[s], -1, cv2.LINE_AA)
            name = s if kind == "exact" else f"{s}, indexed C={candidates}"
            lx = width - right + 10
            if dashed:
                cv2.line(img, (lx, legend_y), (lx + 8, legend_y), COLOURS[s], 2)
                cv2.line(img, (lx + 14, legend_y), (lx + 22, legend_y), COLOURS[s], 2)
            else:
                cv2.line(img, (lx, legend_y), (lx + 22, legend_y), COLOURS[s], 2)
            cv2.putText(img, name, (lx + 28, legend_y + 4), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
            legend_y += 20
    tmp = sys.argv[1] + ".tmp.png"  # written whole, then renamed (docs/conventions.md)
    if not cv2.imwrite(tmp, img):
        sys.exit(f"{sys.argv[1]}: cannot write")
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.replace(tmp, sys.argv[1])
    print(f"wrote {sys.argv[1]}")


if __name__ == "__main__":
    main()
