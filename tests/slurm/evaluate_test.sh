#!/usr/bin/env bash
# Integration test: `handdb evaluate --slurm` against a real single-node Slurm that this
# test starts (scripts/slurm_local.sh) and stops on every exit path, like generate_test.sh.
#   1. a tiny database and test set evaluated on Slurm (3 array tasks + the merge job) give the
#      report of a local `handdb evaluate`: the same text (but the speed line), the same --json
#      (but the run-specific timing fields, docs/cluster.md), byte-identical plots;
#      a re-run with every part complete submits only the merge job;
#   2. a task that fails is reported with its task number and log path; the re-run submits only
#      that task and gives the same report;
#   3. the merge refuses a missing part and a part of another evaluation with one line naming
#      the file; a dry run prints the array and the afterok merge job;
#   4. `handdb evaluate DB --photos DIR --keypoints K --slurm` (3 tasks + merge) gives the report
#      of a local --photos run: text (but the speed line), --json (but timing), --out images byte
#      for byte; a re-run with every part complete submits only the merge job.
# Usage: evaluate_test.sh HANDDB_EXE SOURCE_DIR   (exit 77 = skipped)
set -euo pipefail
# shellcheck source=tests/slurm/lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
slurm_test_args "$@"
slurm_test_require
slurm_test_start handdb-slurm-eval-test

# Everything below runs in $work with relative paths, as a user would type them: the report names
# the database and the test set by these paths, on Slurm as locally.
cd "$work"

step "tiny database (2 shapes x 20 directions x 8 rolls) and test set (8 views, no photos)"
cat >db.json <<JSON
{"name": "slurm-eval-test", "seed": 21,
 "shapes": {"method": "basic", "names": ["flat", "fist"]},
 "views": {"method": "fibonacci", "count": 20},
 "rolls": 8, "unit_size": 20, "render": {"resolution": 128}}
JSON
cat >ts.json <<JSON
{"format": "handdb-testset-config", "version": 1, "name": "slurm-eval-test", "seed": 4242,
 "count": 8, "basic_fraction": 0.5, "basic_names": ["flat", "fist"],
 "hand_model": "configs/hands/webxr_generic_right.json", "shapes": "configs/shapes/basic.json",
 "render": {"resolution": 128}, "photo": {"samples": 1}, "unit_size": 8}
JSON
"$HANDDB" generate db.json --out db --jobs 2 --quiet >/dev/null
"$HANDDB" testset ts.json --out ts --no-photos --jobs 1 --quiet >/dev/null

# The report without the fields that depend on how the work ran (docs/cluster.md lists them).
strip_json() {
  "$PY" - "$1" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
for k in ("search_seconds", "input_seconds", "wall_seconds", "queries_per_second",
          "end_to_end_queries_per_second"):
    del doc["timing"][k]
for v in doc["views"]:
    del v["search_seconds"], v["input_seconds"]
print(json.dumps(doc, indent=1, sort_keys=True))
PY
}
# $1 (text report), $2 (JSON), $3 (plots dir) equal the local run's.
same_as_local() {
  diff <(grep -v '^speed ' local.txt) <(grep -v '^speed ' "$1") || die "$1: text report differs"
  [ "$(grep -c '^speed ' "$1")" -eq 1 ] || die "$1: no speed line"
  diff <(strip_json local.json) <(strip_json "$2") || die "$2: JSON report differs"
  local f n=0
  for f in local_plots/*.png; do
    cmp "$f" "$3/$(basename "$f")" || die "$3/$(basename "$f") differs from the local plot"
    n=$((n + 1))
  done
  [ "$n" -ge 4 ] || die "expected at least 4 plots, got $n"
  echo "$1, $2, $3 ($n plots): same as the local run"
}

step "local evaluation (reference)"
"$HANDDB" evaluate db ts --threads 1 --json local.json --plots local_plots >local.txt 2>/dev/null
grep -q "^Table 1" local.txt || die "local run: no Table 1"

step "case 1: evaluate on Slurm (3 tasks), compare"
"$HANDDB" evaluate db ts --threads 1 --json s1.json --plots s1_plots --slurm --tasks 3 --wait \
  --poll 0.5 >s1.txt 2>s1.err || { cat s1.err; die "case 1: evaluate --slurm failed"; }
grep -q "submitted 3 of 3 tasks (0-2)" s1.err || die "case 1: expected 3 tasks submitted"
same_as_local s1.txt s1.json s1_plots
w1="$(ls -d "$work"/ts/slurm-evaluations/*)"
[ "$(ls "$w1/parts")" = "$(printf 'part-00000.json\npart-00001.json\npart-00002.json')" ] ||
  die "case 1: parts in $w1/parts"
# Every part is a schema'd file of its own slice.
"$PY" - "$w1/parts" <<'PY' || die "case 1: part contents"
import json, sys, os
seen = []
for t in range(3):
    p = json.load(open(os.path.join(sys.argv[1], "part-%05d.json" % t)))
    assert p["format"] == "handdb-evaluation-part" and p["task"] == t and p["tasks"] == 3, p["task"]
    seen += [v["index"] for v in p["views"]]
    assert [v["index"] for v in p["views"]] == list(range(t, 8, 3)), p["views"]
assert sorted(seen) == list(range(8)), seen
PY
# A re-run with every part complete submits only the merge job and prints the same report.
rm -rf s1_plots s1.json
"$HANDDB" evaluate db ts --threads 1 --json s1.json --plots s1_plots --slurm --tasks 3 --wait \
  --poll 0.5 >s1b.txt 2>s1b.err || { cat s1b.err; die "case 1: re-run failed"; }
grep -q "submitted 0 of 3 tasks (none)" s1b.err || die "case 1: re-run should submit no task"
same_as_local s1b.txt s1.json s1_plots

step "case 2: a failing task is reported, the re-run completes only it"
# A directory where task 1's part must go makes its write fail (a real I/O error).
mkdir -p w2/parts/part-00001.json/blocker
if "$HANDDB" evaluate db ts --threads 1 --json s2.json --slurm --tasks 3 --work w2 --wait \
  --poll 0.5 -q >s2.txt 2>s2.err; then
  die "case 2: evaluate should fail while task 1 cannot write its part"
fi
cat s2.err
log2="$work/w2/logs/part-00001.log"
grep -qF "handdb evaluate: task 1: exit code 1 from handdb unit evaluate" s2.err ||
  die "case 2: no task 1 failure"
grep -qF "log: $log2" s2.err || die "case 2: no log path for task 1"
grep -q "part-00001.json" "$log2" || die "case 2: the task log does not name the part"
[ "$(grep -c '^handdb evaluate: task ' s2.err)" -eq 1 ] || die "case 2: only task 1 failed"
[ ! -e s2.json ] || die "case 2: no report may be written while a part is missing"
rm -rf w2/parts/part-00001.json
"$HANDDB" evaluate db ts --threads 1 --json s2.json --plots s2_plots --slurm --tasks 3 --work w2 \
  --wait --poll 0.5 >s2b.txt 2>s2b.err || { cat s2b.err; die "case 2: re-run failed"; }
grep -qF "earlier Slurm run: task 1:" s2b.err || die "case 2: re-run does not report the earlier failure"
grep -q "submitted 1 of 3 tasks (1)" s2b.err || die "case 2: re-run should submit task 1 only"
same_as_local s2b.txt s2.json s2_plots

step "case 3: bad parts, dry run"
cp -r w2 w3
rm w3/parts/part-00002.json
if "$HANDDB" unit evaluate-merge db ts --tasks 3 --work w3 -q 2>s3.err; then die "case 3: merge of a missing part"; fi
[ "$(cat s3.err)" = "handdb unit evaluate-merge: w3/parts/part-00002.json: missing (task 2 of 3 has not written its part)" ] ||
  die "case 3: missing part: $(cat s3.err)"
if "$HANDDB" unit evaluate-merge db ts --tasks 3 --work w2 --d 20 -q 2>s3b.err; then die "case 3: merge with other options"; fi
[ "$(wc -l <s3b.err)" -eq 1 ] || die "case 3: expected one line"
grep -qF "w2/parts/part-00000.json: a part of another evaluation: made with other evaluation options (max_joint_distance_deg: 15.0 vs 20.0)" s3b.err ||
  die "case 3: other options: $(cat s3b.err)"
"$HANDDB" evaluate db ts --slurm --dry-run --tasks 3 --max-parallel 2 --partition local \
  --time 0:10:00 --work w4 >dry.txt
grep -q -- "--array=0-2%2" dry.txt || die "dry run: no --array=0-2%2"
grep -q -- "--dependency=afterok:" dry.txt || die "dry run: no afterok dependency"
grep -q -- "#SBATCH --partition=local" w4/evaluate-array.sbatch || die "dry run: no partition"
[ ! -e w4/jobs.json ] || die "dry run submitted jobs"

step "case 4: --photos on Slurm (3 tasks), compare with a local --photos run"
# Real photos (tests/data/photos, with their licence) filed under the database's two shapes, and
# annotations of two of them: only the agreement of the two runs matters here, not the scores.
mkdir -p photos/flat photos/fist
cp "$SRC"/tests/data/photos/asl-digits/asl-5/*.JPG photos/flat/
cp "$SRC"/tests/data/photos/asl-digits/asl-0/*.JPG photos/fist/
"$PY" - photos >kp.json <<'PY'
import json, os, sys
names = sorted(os.listdir(os.path.join(sys.argv[1], "flat")))[:2]
kps = [[30 + 2 * k, 20 + 3 * (k % 5)] for k in range(21)]
kps[4].append(False)
print(json.dumps({"format": "handdb-photo-keypoints", "version": 1,
                  "images": {"flat/" + n: kps for n in names}}))
PY
strip_photo_json() {
  "$PY" - "$1" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
for k in ("search_seconds", "input_seconds", "wall_seconds", "queries_per_second",
          "end_to_end_queries_per_second"):
    del doc["timing"][k]
for p in doc["photos"]:
    del p["search_seconds"], p["input_seconds"]
print(json.dumps(doc, indent=1, sort_keys=True))
PY
}
# $1 (text), $2 (JSON), $3 (--out dir) equal the local --photos run's.
same_as_local_photos() {
  diff <(grep -v '^speed ' local_photos.txt) <(grep -v '^speed ' "$1") || die "$1: text report differs"
  diff <(strip_photo_json local_photos.json) <(strip_photo_json "$2") || die "$2: JSON report differs"
  local f
  for f in confusion.png successes.png failures.png; do
    cmp "local_photos/$f" "$3/$f" || die "$3/$f differs from the local image"
  done
  echo "$1, $2, $3: same as the local --photos run"
}
"$HANDDB" evaluate db --photos photos --keypoints kp.json --threads 1 --json local_photos.json \
  --out local_photos >local_photos.txt 2>/dev/null
grep -q "^2D keypoints (kp.json): 2 of 6 photos annotated" local_photos.txt ||
  die "local --photos run: no keypoint section"
"$HANDDB" evaluate db --photos photos --keypoints kp.json --threads 1 --json s4.json --out s4_out \
  --slurm --tasks 3 --wait --poll 0.5 >s4.txt 2>s4.err || { cat s4.err; die "case 4: evaluate --photos --slurm failed"; }
grep -q "submitted 3 of 3 tasks (0-2)" s4.err || die "case 4: expected 3 tasks submitted"
same_as_local_photos s4.txt s4.json s4_out
w4="$(ls -d "$work"/slurm-evaluations/*)"
[ "$(ls "$w4/parts")" = "$(printf 'part-00000.json\npart-00001.json\npart-00002.json')" ] ||
  die "case 4: parts in $w4/parts"
"$PY" - "$w4/parts" <<'PY' || die "case 4: part contents"
import json, sys, os
seen = []
for t in range(3):
    p = json.load(open(os.path.join(sys.argv[1], "part-%05d.json" % t)))
    assert p["format"] == "handdb-photo-evaluation-part" and p["task"] == t and p["tasks"] == 3
    assert len(p["photos"]) == 2, p["photos"]
    seen += [x["photo"] for x in p["photos"]]
assert len(set(seen)) == 6, seen
PY
rm -rf s4_out s4.json
"$HANDDB" evaluate db --photos photos --keypoints kp.json --threads 1 --json s4.json --out s4_out \
  --slurm --tasks 3 --wait --poll 0.5 >s4b.txt 2>s4b.err || { cat s4b.err; die "case 4: re-run failed"; }
grep -q "submitted 0 of 3 tasks (none)" s4b.err || die "case 4: re-run should submit no task"
same_as_local_photos s4b.txt s4.json s4_out

step "all Slurm evaluation cases passed"
