#!/usr/bin/env bash
# Real-photo regression test: a database of the ten ASL digit shapes (86
# directions x 48 rolls, real Blender renders), then `handdb evaluate --photos` on the 30 real
# photos of tests/data/photos/asl-digits. Asserts a floor well below the measured accuracy, so it
# catches a broken photo path or search, not noise.
# Usage: real_photos_test.sh HANDDB_EXE SOURCE_DIR   (exit 77 = skipped: no Blender)
set -euo pipefail
HANDDB="$(realpath "${1:?usage: real_photos_test.sh HANDDB_EXE SOURCE_DIR}")"
SRC="$(realpath "${2:?usage: real_photos_test.sh HANDDB_EXE SOURCE_DIR}")"
command -v "${HANDDB_BLENDER:-blender}" >/dev/null || { echo "SKIP: blender not installed"; exit 77; }
# Floors (top-1 and top-5 shape accuracy, %): with the digits fitted to the development photos
# (these 30 among them, so in-sample) and `evaluate --photos` ranking shapes (top-5 = the 5
# nearest of this database's 10 shapes; chance 10% / 50%), the test measures 93.3% / 100.0%; the
# digits as described, before fitting, gave 53.3% / 70.0% (16 / 21 of 30) counted over the
# nearest views. The floors sit well below the fitted figures, so
# a broken photo path, search or shape library fails the test and a changed view or two does not.
# The photos are right hands and the floors were measured so: --hand right, not the default
# either.
TOP1_FLOOR=50
TOP5_FLOOR=80

work="$(mktemp -d "${TMPDIR:-/tmp}/handdb-photos-test.XXXXXX")"
cleanup() {
  local rc=$?
  if [ "$rc" -eq 0 ]; then rm -rf "$work"; else echo "files kept in $work" >&2; fi
}
trap cleanup EXIT

cat >"$work/config.json" <<JSON
{"name": "asl-digits-test", "seed": 0,
 "shapes": {"method": "basic", "names": ["asl-0", "asl-1", "asl-2", "asl-3", "asl-4",
                                          "asl-5", "asl-6", "asl-7", "asl-8", "asl-9"]},
 "views": {"method": "fibonacci", "count": 86},
 "rolls": 48, "unit_size": 430, "render": {"resolution": 256}}
JSON
start=$(date +%s)
"$HANDDB" generate "$work/config.json" --out "$work/db" --jobs 2 > "$work/generate.log" 2>&1 \
  || { tail -20 "$work/generate.log"; echo "FAIL: generate" >&2; exit 1; }
echo "generate: $(( $(date +%s) - start )) s"
start=$(date +%s)
"$HANDDB" evaluate "$work/db" --photos "$SRC/tests/data/photos/asl-digits" --hand right \
  --json "$work/photos.json" \
  > "$work/evaluate.txt" 2> "$work/evaluate.log" \
  || { cat "$work/evaluate.log"; echo "FAIL: evaluate --photos" >&2; exit 1; }
echo "evaluate: $(( $(date +%s) - start )) s"
sed -n '/shape accuracy/,/^speed/p' "$work/evaluate.txt"
/usr/bin/python3 - "$work/photos.json" "$TOP1_FLOOR" "$TOP5_FLOOR" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
# The test command installs the landmark model (scripts/deps.sh): the photos must be re-ranked
# by their hand landmarks, not silently by D_c alone.
if not doc["search"]["query_options"].get("landmarks"):
    sys.exit("FAIL: the photos were not re-ranked by hand landmarks (is the model installed?)")
rate = {a["k"]: a["rate"] for a in doc["accuracy"]}
top1, top5 = 100 * rate[1], 100 * rate[5]
print(f"top-1 {top1:.1f}% (floor {sys.argv[2]}%), top-5 {top5:.1f}% (floor {sys.argv[3]}%)")
if top1 < float(sys.argv[2]) or top5 < float(sys.argv[3]):
    sys.exit("FAIL: real-photo accuracy below the floor")
PY

# The fitted pose on the same photos, as one batch: every photo the network sees gets a pose
# whose keypoints lie nearer its landmarks than the top match's did, inside the picture; the
# pose exports as a glTF binary; Python's Match.fit is the CLI's.
"$HANDDB" query "$work/db" "$SRC/tests/data/photos/asl-digits"/*/* --hand right --top 3 --json -q \
  > "$work/fit.jsonl" || { echo "FAIL: query with the pose fit" >&2; exit 1; }
photo="$(ls "$SRC/tests/data/photos/asl-digits/asl-5"/* | head -1)"
"$HANDDB" query "$work/db" "$photo" --hand right --export "$work/pose.glb" -q > /dev/null \
  || { echo "FAIL: query --export" >&2; exit 1; }
PYTHONPATH="${HANDDB_PYTHONPATH:-}" /usr/bin/python3 - "$work/fit.jsonl" "$work/pose.glb" "$work/db" "$photo" <<'PY'
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
fitted = [d for d in lines if "pose" in d]
print(f"pose fit: {len(fitted)} of {len(lines)} photos fitted")
if len(fitted) < 0.8 * len(lines):
    sys.exit("FAIL: fewer than 80% of the photos got a fitted pose")
for d in fitted:
    p = d["pose"]
    err = p["landmark_error_px"]
    if not (err["fitted"] < err["start"]) or len(p["keypoints"]) != 21:
        sys.exit(f"FAIL: {d['picture']}: the fit did not move the pose towards the landmarks: {err}")
    w, h = d["query"]["width"], d["query"]["height"]
    if not all(-0.25 * w <= x <= 1.25 * w and -0.25 * h <= y <= 1.25 * h
               for x, y in p["keypoints_image_px"]):
        sys.exit(f"FAIL: {d['picture']}: fitted keypoints far outside the picture")
with open(sys.argv[2], "rb") as f:
    if f.read(4) != b"glTF":
        sys.exit("FAIL: --export did not write a glTF binary")
try:
    import handdb
except ImportError:
    print("python module not on PYTHONPATH: Match.fit not checked")
    sys.exit(0)
db = handdb.Database(sys.argv[3])
m = db.search(sys.argv[4], top_k=3, hand="right")[0]
if m.fit is None or not m.fit["fitted"] or m.to_dict()["fit"] != m.fit:
    sys.exit("FAIL: Python's Match.fit")
PY
