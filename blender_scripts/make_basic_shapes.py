"""Writes configs/shapes/basic.json: the named basic hand shapes as 20-D joint vectors.

    /usr/bin/python3 blender_scripts/make_basic_shapes.py

Finger and thumb postures are given in degrees (DOF order of docs/conventions.md); for shapes in
which the thumb tip touches a finger tip (asl-0, asl-6..9, pinch) the thumb's four angles are
searched on a grid so the two tip keypoints are TOUCH_DIST apart (forward kinematics of the hand
model). Look at docs/images/basic_shapes.png (blender_scripts/contact_sheet.py) after a change.
"""
import itertools
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from handdb_blender import kinematics as K  # noqa: E402
from handdb_blender.plan import REPO_ROOT, write_atomic  # noqa: E402

model = json.load(open(os.path.join(REPO_ROOT, "configs/hands/webxr_generic_right.json")))
lim = [(d["min"], d["max"]) for d in model["dofs"]]
STRAIGHT = (0, 0, 0, 0)
CURL = (85, 0, 100, 60)      # finger folded into the palm
HALF = (40, 0, 50, 30)

def shape(thumb, index=STRAIGHT, middle=STRAIGHT, ring=STRAIGHT, pinky=STRAIGHT):
    v = list(thumb) + list(index) + list(middle) + list(ring) + list(pinky)
    return [math.radians(x) for x in v]

def ab(f, a):
    return (f[0], a, f[2], f[3])

TH_FIST = (45, 5, 45, 30)      # thumb over the curled fingers
TH_PALM = (55, 15, 60, 50)     # thumb folded across the palm (asl-4, B)
TH_OUT = (-15, 10, 0, 0)       # thumb out to the side
TH_UP = (35, -10, -15, -10)    # thumb straight up, along the fingers (thumbs-up)

S = {}
S["flat"] = shape((0, 0, 0, 0), ab(STRAIGHT, -5), ab(STRAIGHT, 0), ab(STRAIGHT, -5), ab(STRAIGHT, -8))
S["fist"] = shape(TH_FIST, CURL, CURL, CURL, CURL)
S["asl-1"] = shape(TH_FIST, STRAIGHT, CURL, CURL, CURL)
S["asl-2"] = shape(TH_FIST, ab(STRAIGHT, 10), ab(STRAIGHT, -10), CURL, CURL)
S["asl-3"] = shape(TH_OUT, ab(STRAIGHT, 10), ab(STRAIGHT, -10), CURL, CURL)
S["asl-4"] = shape(TH_PALM, ab(STRAIGHT, 8), STRAIGHT, ab(STRAIGHT, 8), ab(STRAIGHT, 12))
S["asl-5"] = shape(TH_OUT, ab(STRAIGHT, 18), STRAIGHT, ab(STRAIGHT, 12), ab(STRAIGHT, 22))
S["claw"] = shape((10, 30, 30, 40), ab((10, 0, 80, 70), 12), (10, 0, 80, 70), ab((10, 0, 80, 70), 10), ab((10, 0, 80, 70), 18))
S["L"] = shape((-20, 30, -10, 0), STRAIGHT, CURL, CURL, CURL)
S["Y"] = shape(TH_OUT, CURL, CURL, CURL, ab(STRAIGHT, 20))
S["I-love-you"] = shape(TH_OUT, ab(STRAIGHT, 8), CURL, CURL, ab(STRAIGHT, 20))
S["thumbs-up"] = shape(TH_UP, CURL, CURL, CURL, CURL)
S["A"] = shape((25, -30, 10, 20), CURL, CURL, CURL, CURL)
S["B"] = shape(TH_PALM, ab(STRAIGHT, -5), STRAIGHT, ab(STRAIGHT, -5), ab(STRAIGHT, -8))
S["C"] = shape((10, 35, 10, 15), (30, 0, 45, 30), (30, 0, 45, 30), (30, 0, 45, 30), (30, 0, 45, 30))
S["E"] = shape((50, 20, 60, 40), (60, 0, 100, 80), (60, 0, 100, 80), (60, 0, 100, 80), (60, 0, 100, 80))
S["X"] = shape(TH_FIST, (20, 0, 90, 60), CURL, CURL, CURL)
S["horns"] = shape(TH_FIST, ab(STRAIGHT, 10), CURL, CURL, ab(STRAIGHT, 20))
S["gun"] = shape((-15, 10, 0, 0), STRAIGHT, STRAIGHT, CURL, CURL)
# Fingers halfway to a fist, thumb open. (Its thumb was first bent towards the fingertips,
# (15, 20, 20, 20): that made it a second O, its thumb tip nearer the index tip than asl-0's,
# and the nearest wrong shape of most O photos; docs/hand_model.md.)
S["half-open"] = shape(STRAIGHT, HALF, HALF, HALF, HALF)

# Shapes in which the thumb tip touches a finger tip: search the thumb's 4 DOFs (and the
# touched finger's flexion) so the two tip keypoints are TOUCH_DIST apart.
TOUCH_DIST = 0.016
def touch(base, finger, finger_flex):
    fi = {"index": 4, "middle": 8, "ring": 12, "pinky": 16}[finger]
    tip = {"index": 8, "middle": 12, "ring": 16, "pinky": 20}[finger]
    j = np.array(base, dtype=float)
    j[fi:fi + 4] = [math.radians(x) for x in finger_flex]
    best = None
    grid = [np.radians(np.arange(lo, hi + 1e-9, st)) for lo, hi, st in ((0, 60, 5), (0, 60, 5), (0, 80, 10), (0, 60, 10))]
    for t in itertools.product(*grid):
        j[0:4] = t
        k = K.keypoints(model, j)
        err = abs(np.linalg.norm(k[4] - k[tip]) - TOUCH_DIST)
        # prefer small angles among near-equal solutions
        cost = err + 0.002 * sum(abs(x) for x in t)
        if best is None or cost < best[0]:
            best = (cost, err, j.copy())
    print(finger, "touch err", round(best[1], 4), np.round(np.degrees(best[2][0:4])), file=sys.stderr)
    return [float(x) for x in best[2]]

S["asl-0"] = touch(shape(STRAIGHT, (30, 0, 50, 30), (35, 0, 50, 30), (40, 0, 50, 30), (45, 0, 50, 30)), "index", (30, 0, 50, 30))
S["asl-6"] = touch(shape(STRAIGHT, ab(STRAIGHT, 8), STRAIGHT, ab(STRAIGHT, 8), STRAIGHT), "pinky", (55, -10, 60, 30))
S["asl-7"] = touch(shape(STRAIGHT, ab(STRAIGHT, 8), STRAIGHT, STRAIGHT, ab(STRAIGHT, 15)), "ring", (55, -5, 60, 30))
S["asl-8"] = touch(shape(STRAIGHT, ab(STRAIGHT, 8), STRAIGHT, ab(STRAIGHT, 8), ab(STRAIGHT, 15)), "middle", (55, 0, 60, 30))
S["asl-9"] = touch(shape(STRAIGHT, STRAIGHT, ab(STRAIGHT, -3), ab(STRAIGHT, 8), ab(STRAIGHT, 15)), "index", (50, 0, 60, 30))
S["pinch"] = touch(shape(STRAIGHT, STRAIGHT, HALF, HALF, HALF), "index", (45, 0, 45, 20))

# The ASL digits as people make them (docs/hand_model.md "Fitted to real
# photographs"): the descriptions above were the starting points; each digit's 20 angles were then
# fitted by coordinate descent (10 deg steps, two sweeps, then 5 deg, one sweep) to minimise the mean
# exact chamfer distance between the rendered shape (best of 86 directions x 48 rolls per photo) and
# 10 real photos of it, from 10 people (the even-numbered half of ../shared/photos/asl-digits/, the
# Sign Language Digits Dataset, Apache-2.0). The seven digits that half still confused (0, 4-9) were
# then refitted from there on all 20 people (5 deg steps until no step helps); 1-3 were already the
# top match for 16-19 of 20 and kept. Degrees, DOF order of docs/conventions.md.
FITTED_ASL = {
    "asl-0": [35, 15, 5, -5, 30, 0, 50, 15, 35, 5, 50, 45, 40, 10, 40, 40, 45, -10, 45, 40],
    "asl-1": [35, -25, 30, 45, -5, 10, 0, -5, 90, -15, 80, 40, 90, -15, 75, 35, 90, -15, 95, 75],
    "asl-2": [45, -20, 45, 10, 0, 5, 0, -10, 0, -10, 0, -10, 90, 5, 80, 30, 90, -15, 80, 30],
    "asl-3": [-15, -5, 0, -5, 0, 10, 0, 15, -20, -10, 0, -5, 60, 5, 95, 15, 70, -5, 70, 20],
    "asl-4": [55, -5, 40, 60, -10, 8, 0, -5, 0, 0, 0, 0, 10, -2, 0, -10, 0, 12, 20, 10],
    "asl-5": [-15, 0, 5, 20, 0, 8, 15, 10, 0, 0, 15, 5, -20, 2, 30, 25, 0, 12, 30, 0],
    "asl-6": [60, 15, 10, 25, 5, 8, 10, -5, 0, 0, 0, 25, 0, -2, 0, 10, 85, -5, 70, 20],
    "asl-7": [55, 10, -20, 35, -10, 8, 15, -10, -10, 0, 5, 0, 35, -10, 95, 50, 0, 5, 20, 30],
    "asl-8": [45, 20, 0, -20, 0, 8, 0, 15, 45, 15, 60, 50, 0, -7, 5, 15, 15, 5, 0, 5],
    "asl-9": [35, -5, -5, -5, 45, -15, 60, 20, -5, -13, 0, 0, 0, 3, 0, -10, 0, 5, 15, -10],
}
for name, degrees in FITTED_ASL.items():
    S[name] = [math.radians(v) for v in degrees]

def dumps(o, ind=0):
    sp = "  " * ind
    if isinstance(o, dict):
        if not o: return "{}"
        items = [f'{sp}  {json.dumps(k)}: {dumps(v, ind + 1)}' for k, v in o.items()]
        return "{\n" + ",\n".join(items) + "\n" + sp + "}"
    if isinstance(o, list):
        flat = json.dumps(o)
        if (len(flat) <= 100 or all(isinstance(x, (int, float)) for x in o)) and not any(isinstance(x, (dict, list)) for x in o) or (len(flat) <= 100 and not any(isinstance(x, dict) for x in o)):
            return flat
        return "[\n" + ",\n".join(sp + "  " + dumps(x, ind + 1) for x in o) + "\n" + sp + "]"
    return json.dumps(o)

order = ["asl-0", "asl-1", "asl-2", "asl-3", "asl-4", "asl-5", "asl-6", "asl-7", "asl-8", "asl-9",
         "flat", "fist", "claw", "pinch", "L", "Y", "I-love-you", "thumbs-up", "A", "B", "C", "E", "X",
         "horns", "gun", "half-open"]
assert set(order) == set(S), set(S) ^ set(order)
out = []
for i, n in enumerate(order):
    j = [min(max(v, lo), hi) for v, (lo, hi) in zip(S[n], lim)]
    # (1e-6: a limit stored in radians to 6 places vs the same angle given in whole degrees)
    assert all(abs(a - b) < 1e-6 for a, b in zip(j, S[n])), (n, K.within_limits(model, S[n]))
    out.append({"id": i, "name": n, "joints": [round(v, 6) for v in j]})
doc = {"format": "handdb-shapes", "version": 1, "hand_model": "configs/hands/webxr_generic_right.json",
       "units": "radians", "shapes": out}
write_atomic(os.path.join(REPO_ROOT, "configs/shapes/basic.json"), (dumps(doc) + "\n").encode())
print(len(out), "shapes")
