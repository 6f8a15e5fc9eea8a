#!/usr/bin/env python3
"""Reads bench/fit_study's JSON lines and prints what the fits gain and where their 3D error lies.

    python3 bench/fit_study.py lines.jsonl [--variant NAME ...]

Errors are root-relative 3D keypoint errors in wrist-to-middle-knuckle lengths of the truth (the
`_wm` numbers of `handdb evaluate`), median over the test views; each view's unfitted answer is
its top match, as `handdb evaluate` counts it. "plane" and "depth" are the same error with only
the camera's x, y or only its z compared. The network's depths are compared with the truth's
root-relative depths: its screen depths as they are (normalised px), its world joints scaled by
the truth's wrist-to-middle-knuckle length over theirs.
"""
import argparse
import json
import math
import statistics

TIPS = [4, 8, 12, 16, 20]
BASES = [1, 5, 9, 13, 17]


def wm(p):
    return math.dist(p[0], p[9])


def error(a, t, axes=(0, 1, 2)):
    s = 0.0
    for k in range(1, 21):
        s += math.sqrt(sum(((a[k][c] - a[0][c]) - (t[k][c] - t[0][c])) ** 2 for c in axes))
    return s / 20 / wm(t)


def med(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    return statistics.median(xs) if xs else float("nan")


def choose(fits, n, key):
    cands = [(key(f), i) for i, f in enumerate(fits[:n]) if f.get("fitted")]
    return min(cands)[1] if cands else None


def pearson(x, y):
    mx, my = statistics.fmean(x), statistics.fmean(y)
    sxy = sum((a - mx) * (b - my) for a, b in zip(x, y))
    sxx = sum((a - mx) ** 2 for a in x)
    syy = sum((b - my) ** 2 for b in y)
    return sxy / math.sqrt(sxx * syy) if sxx > 0 and syy > 0 else float("nan")


def depth_agreement(lines, min_presence):
    """Sign agreement of z(tip) - z(base) per finger, and the correlation of root-relative z."""
    rows = {"screen": [], "world": []}
    corr = {"screen": [], "world": []}
    for ln in lines:
        if "depth" not in ln or ln.get("presence", 0) < min_presence:
            continue
        t = ln["truth"]
        w = wm(t)
        tz = [(t[k][2] - t[0][2]) / w for k in range(21)]
        sources = {"screen": [(d - ln["depth"][0]) / w for d in ln["depth"]]}
        if "world" in ln:
            wo = ln["world"]
            s = 1.0 / math.dist(wo[0], wo[9])
            sources["world"] = [(wo[k][2] - wo[0][2]) * s for k in range(21)]
        for name, z in sources.items():
            if any(math.isnan(v) for v in z):
                continue
            corr[name].append(pearson(z[1:], tz[1:]))
            for b, tip in zip(BASES, TIPS):
                dt = tz[tip] - tz[b]
                dn = z[tip] - z[b]
                rows[name].append((abs(dt), (dt > 0) == (dn > 0), abs(dn - dt)))
    for name in rows:
        r = rows[name]
        if not r:
            continue
        big = [x for x in r if x[0] >= 0.3]
        print(
            f"  {name:6s}: fingers {len(r)}, sign agrees {sum(x[1] for x in r) / len(r):.2f}; "
            f"where |dz truth| >= 0.3: {len(big)}, agrees "
            f"{(sum(x[1] for x in big) / len(big)) if big else float('nan'):.2f}; "
            f"median |dz error| {med([x[2] for x in r]):.3f}; "
            f"median per-view corr of root-relative z {med(corr[name]):.2f}"
        )


def summarise(lines, variant, ns=(1, 3, 5, 10)):
    top1, best10, plane, depth = [], [], [], []
    per_n = {n: [] for n in ns}
    per_n_depth = {n: [] for n in ns}
    first_fit, oracle3, oracle10 = [], [], []
    fit_plane, fit_depth = [], []
    best_plane, best_depth = [], []
    for ln in lines:
        if "matches" not in ln:
            continue
        t = ln["truth"]
        ms = ln["matches"]
        top = ms[0]["keypoints"]
        top1.append(error(top, t))
        best10.append(min(error(m["keypoints"], t) for m in ms[:10]))
        plane.append(error(top, t, (0, 1)))
        depth.append(error(top, t, (2,)))
        v = ln["fits"].get(variant)
        if v is None:
            continue
        fits = v["fits"]
        errs = [error(f["keypoints"], t) if f.get("fitted") else None for f in fits]
        for n in ns:
            i = choose(fits, n, lambda f: f["final"])
            per_n[n].append(errs[i] if i is not None else top1[-1])
            per_n_depth[n].append(
                error(fits[i]["keypoints"], t, (2,)) if i is not None else depth[-1])
        i = choose(fits, 3, lambda f: f["final"])
        if i is not None:
            fit_plane.append(error(fits[i]["keypoints"], t, (0, 1)))
            fit_depth.append(error(fits[i]["keypoints"], t, (2,)))
        ok = [e for e in errs if e is not None]
        if ok:
            first_fit.append(next(e for e in errs if e is not None))
            oracle3.append(min([e for e in errs[:3] if e is not None] or [float("nan")]))
            oracle10.append(min(ok))
            j = min(range(len(errs)), key=lambda k: errs[k] if errs[k] is not None else 1e9)
            best_plane.append(error(fits[j]["keypoints"], t, (0, 1)))
            best_depth.append(error(fits[j]["keypoints"], t, (2,)))
    print(f"variant {variant}: {len(top1)} views")
    print(f"  top-1 {med(top1):.3f} (plane {med(plane):.3f}, depth {med(depth):.3f}); "
          f"best of top 10 stored views {med(best10):.3f}")
    print("  least final cost among N fits: " +
          ", ".join(f"N={n} {med(per_n[n]):.3f} (depth {med(per_n_depth[n]):.3f})" for n in ns))
    print(f"  first fit {med(first_fit):.3f}; oracle of 3 {med(oracle3):.3f}, of 10 "
          f"{med(oracle10):.3f}")
    print(f"  the N=3 answer: plane {med(fit_plane):.3f}, depth {med(fit_depth):.3f}; "
          f"the oracle's fit of 10: plane {med(best_plane):.3f}, depth {med(best_depth):.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("lines")
    ap.add_argument("--variant", action="append")
    ap.add_argument("--min-presence", type=float, default=0.5)
    args = ap.parse_args()
    lines = [json.loads(x) for x in open(args.lines)]
    variants = args.variant or list(next(ln for ln in lines if "fits" in ln)["fits"])
    print("depth agreement of the network with the truth (presence >= "
          f"{args.min_presence}):")
    depth_agreement(lines, args.min_presence)
    for v in variants:
        summarise(lines, v)


if __name__ == "__main__":
    main()
