#!/usr/bin/env bash
# Integration test: `handdb generate` on a tiny real Blender plan, and kill -9 at many
# moments (during render, convert, manifest writing), each time checking that whatever manifest
# exists lists only complete, valid shards; the final rerun must give shards and a manifest
# byte-identical to an uninterrupted run, which `handdb validate` accepts. Also `handdb show`.
# Usage: generate_resume_test.sh HANDDB_EXE   (exit 77 = skipped: no Blender)
set -euo pipefail
HANDDB="$(realpath "${1:?usage: generate_resume_test.sh HANDDB_EXE}")"
command -v "${HANDDB_BLENDER:-blender}" >/dev/null || { echo "SKIP: blender not installed"; exit 77; }

t_start=$(date +%s)
step() { echo "--- [$(( $(date +%s) - t_start ))s] $*"; }
die() { echo "FAIL: $*" >&2; exit 1; }
work="$(mktemp -d "${TMPDIR:-/tmp}/handdb-generate-test.XXXXXX")"
cleanup() {
  local rc=$?
  if [ "$rc" -eq 0 ]; then rm -rf "$work"; else echo "files kept in $work" >&2; fi
}
trap cleanup EXIT

# 2 shapes x 4 directions in 3 units (3 + 3 + 2 renders).
cat >"$work/config.json" <<JSON
{"name": "generate-test", "seed": 5,
 "shapes": {"method": "basic", "names": ["flat", "asl-2"]},
 "views": {"method": "fibonacci", "count": 4},
 "rolls": 6, "unit_size": 3, "render": {"resolution": 128}}
JSON

# The database's files (shards + manifest), as "name checksum" lines.
db_files() { (cd "$1" && sha256sum manifest.json shard-*.hdb); }

# A manifest, when present, must list only shards that exist and pass validation.
check_consistent() {
  local db="$1"
  [ -f "$db/manifest.json" ] || return 0
  "$HANDDB" validate "$db" >/dev/null 2>"$work/validate.err" ||
    die "after a kill, $db/manifest.json lists a bad shard: $(head -3 "$work/validate.err")"
}

step "uninterrupted run"
"$HANDDB" generate "$work/config.json" --out "$work/ref" --jobs 2 --quiet >"$work/ref.out"
grep -q "validated 8 views: ok" "$work/ref.out" || die "unexpected summary: $(cat "$work/ref.out")"
"$HANDDB" validate "$work/ref" >/dev/null
[ "$(ls "$work/ref"/shard-*.hdb | wc -l)" -eq 3 ] || die "expected 3 shards"
db_files "$work/ref" >"$work/ref.sums"

step "handdb show"
"$HANDDB" show "$work/ref" --view 3 --roll 2 --keypoints -o "$work/view.png"
head -c 8 "$work/view.png" | od -An -tx1 | grep -q "89 50 4e 47" || die "show did not write a PNG"
set +e
"$HANDDB" show "$work/ref" --view 99 -o "$work/bad.png" 2>"$work/show.err"; rc=$?
set -e
[ "$rc" -eq 1 ] && grep -q "out of range" "$work/show.err" || die "show --view 99: rc $rc"
[ ! -e "$work/bad.png" ] || die "show wrote a file for a bad view"

step "rerun is a no-op"
"$HANDDB" generate "$work/config.json" --out "$work/ref" --jobs 2 --quiet --json >"$work/rerun.json"
/usr/bin/python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['shards_kept']==3 and d['shards_written']==0, d" "$work/rerun.json"
db_files "$work/ref" | diff -q - "$work/ref.sums" >/dev/null || die "rerun changed the database"

step "kill -9 during generate at increasing delays, rerun after each"
db="$work/killed"
delay=0.3
for i in $(seq 1 40); do
  # In its own process group, so kill -9 takes the Blender workers too (as a lost node would).
  setsid "$HANDDB" generate "$work/config.json" --out "$db" --jobs 2 --quiet >/dev/null 2>&1 &
  pid=$!
  sleep "$delay"
  if kill -0 "$pid" 2>/dev/null; then
    kill -9 -- "-$pid" 2>/dev/null || kill -9 "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    check_consistent "$db"
  else
    wait "$pid" || die "generate failed on attempt $i"
    break
  fi
  delay=$(/usr/bin/python3 -c "print(round($delay * 1.35, 3))")
done
step "final rerun after $i attempts"
"$HANDDB" generate "$work/config.json" --out "$db" --jobs 2 --quiet >/dev/null
db_files "$db" | diff - "$work/ref.sums" || die "resumed database differs from the uninterrupted one"

step "kill -9 during convert (render dir already complete), at fractions of its run time"
conv="$work/conv"
t0=$(date +%s%N)
"$HANDDB" convert "$work/ref/render" --out "$work/conv-timing" --threads 1 --quiet >/dev/null
t_ns=$(( $(date +%s%N) - t0 ))
states=""
for k in $(seq 1 16); do
  rm -rf "$conv"
  if [ $((k % 2)) -eq 0 ]; then  # half the attempts start from a database with a damaged shard
    mkdir -p "$conv" && cp "$work/ref"/manifest.json "$work/ref"/shard-*.hdb "$conv"/
    truncate -s 100 "$conv/shard-00001.hdb"
  fi
  "$HANDDB" convert "$work/ref/render" --out "$conv" --threads 1 --quiet >/dev/null 2>&1 &
  pid=$!
  sleep "$(/usr/bin/python3 -c "print($t_ns * $k / 16 / 1e9)")"
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  [ $((k % 2)) -eq 0 ] || check_consistent "$conv"
  n=$( { find "$conv" -maxdepth 1 -name "shard-*.hdb" 2>/dev/null || true; } | wc -l)
  states="$states $n$( [ -f "$conv/manifest.json" ] && echo M || true)"
done
echo "shards (M: manifest) left by the kills:$states"
"$HANDDB" convert "$work/ref/render" --out "$conv" --quiet >/dev/null
db_files "$conv" | diff - "$work/ref.sums" || die "resumed convert differs from the uninterrupted one"

step "bad input: a truncated EXR fails the run before anything is written"
cp -r "$work/ref/render" "$work/badrun"
exr="$(ls "$work/badrun"/units/u00001/*.exr | head -1)"
truncate -s 2000 "$exr"
set +e
"$HANDDB" convert "$work/badrun" --out "$work/baddb" --quiet 2>"$work/bad.err"; rc=$?
set -e
[ "$rc" -eq 1 ] || die "convert with a truncated EXR: exit $rc"
grep -q "$(basename "$exr")" "$work/bad.err" || die "error does not name the file: $(cat "$work/bad.err")"
[ -z "$(ls -A "$work/baddb" 2>/dev/null)" ] || die "files written despite a bad input"
"$HANDDB" convert "$work/badrun" --out "$work/baddb" --skip-bad --quiet >/dev/null
/usr/bin/python3 -c "
import json,sys; m=json.load(open(sys.argv[1]))
assert m['num_views']==7 and len(m['skipped'])==1 and m['skipped'][0]['file'].endswith(sys.argv[2]), m['skipped']
" "$work/baddb/manifest.json" "$(basename "$exr")"
"$HANDDB" validate "$work/baddb" >/dev/null
step "ok"
