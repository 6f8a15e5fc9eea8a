#!/usr/bin/env bash
# Integration test: `handdb generate --slurm` against a real single-node Slurm that this
# test starts (scripts/slurm_local.sh: munged, slurmctld, slurmd on loopback, all state in a temp
# dir) and stops on every exit path.
#   1. a tiny plan built on Slurm is byte-identical to the same config built locally;
#   2. a unit whose task fails is reported with its unit and log path; the re-run submits only
#      that unit and completes the database;
#   3. an array task killed while it runs (scancel) is reported; the re-run completes only it;
#   4. --index: the final job builds the search index, byte-identical to a local --index build.
# Usage: generate_test.sh HANDDB_EXE SOURCE_DIR   (exit 77 = skipped)
set -euo pipefail
# shellcheck source=tests/slurm/lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
slurm_test_args "$@"
slurm_test_require
slurm_test_start handdb-slurm-test

# 2 shapes x 2 directions, one render per unit: 4 units, 4 array tasks.
cat >"$work/config.json" <<JSON
{"name": "slurm-test", "seed": 11,
 "shapes": {"method": "basic", "names": ["flat", "fist"]},
 "views": {"method": "fibonacci", "count": 2},
 "rolls": 8, "unit_size": 1, "render": {"resolution": 128}}
JSON

# Every shard and the manifest of database $1 equal those of the local build, byte for byte.
same_as_local() {
  local db="$1" f n=0
  for f in "$work/local"/shard-*.hdb "$work/local/manifest.json"; do
    cmp "$f" "$db/$(basename "$f")" || die "$db/$(basename "$f") differs from the local build"
    n=$((n + 1))
  done
  [ "$(ls "$db" | grep -c '^shard-.*\.hdb$')" -eq 4 ] || die "$db: expected 4 shards"
  echo "$db: $n files identical to the local build"
}

json_field() { "$PY" -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))[sys.argv[2]]))' "$@"; }

step "local build (reference)"
"$HANDDB" generate "$work/config.json" --out "$work/local" --jobs 2 --quiet >/dev/null
[ "$(ls "$work/local" | grep -c '^shard-.*\.hdb$')" -eq 4 ] || die "local build: expected 4 shards"

step "case 1: build on Slurm, compare"
"$HANDDB" generate "$work/config.json" --out "$work/s1" --slurm --wait --poll 0.5 --quiet --json \
  >"$work/s1.json"
[ "$(json_field "$work/s1.json" submitted_units)" = "[0, 1, 2, 3]" ] || die "case 1: submitted units"
[ "$(json_field "$work/s1.json" final_job_state)" = '"COMPLETED"' ] || die "case 1: final job"
same_as_local "$work/s1"
# A re-run of a complete database submits nothing.
"$HANDDB" generate "$work/config.json" --out "$work/s1" --slurm --quiet | grep -q "nothing to submit" ||
  die "case 1: re-run of a complete database should submit nothing"
# The dry run of a fresh database prints the array of all units and the afterok final job.
"$HANDDB" generate "$work/config.json" --out "$work/dry" --slurm --dry-run --max-parallel 2 \
  --partition local --time 0:10:00 --quiet >"$work/dry.txt"
grep -q -- "--array=0-3%2" "$work/dry.txt" || die "dry run: no --array=0-3%2"
grep -q -- "--dependency=afterok:" "$work/dry.txt" || die "dry run: no afterok dependency"
grep -q -- "#SBATCH --partition=local" "$work/dry/render/slurm/generate-array.sbatch" ||
  die "dry run: no partition in the script"
[ ! -e "$work/dry/render/slurm/jobs.json" ] || die "dry run submitted jobs"

step "case 2: a failing task is reported, the re-run completes only it"
# A new database from case 1's renders (--work): the tasks only convert. A directory where unit
# 1's shard must go makes its convert step fail (a real I/O error).
mkdir -p "$work/s2/shard-00001.hdb/blocker"
if "$HANDDB" generate "$work/config.json" --out "$work/s2" --work "$work/s1/render" --slurm --wait \
  --poll 0.5 --quiet 2>"$work/s2.err"; then
  die "case 2: generate should fail while unit 1 cannot be written"
fi
cat "$work/s2.err"
log2="$work/s1/render/slurm/logs/u00001.log"
grep -qF "unit 1: exit code 1 from handdb unit convert" "$work/s2.err" || die "case 2: no unit 1 failure"
grep -qF "log: $log2" "$work/s2.err" || die "case 2: no log path for unit 1"
grep -q "shard-00001.hdb" "$log2" || die "case 2: the unit log does not name the shard"
[ "$(grep -c '^handdb generate: unit ' "$work/s2.err")" -eq 1 ] || die "case 2: only unit 1 failed"
rm -rf "$work/s2/shard-00001.hdb"
"$HANDDB" generate "$work/config.json" --out "$work/s2" --work "$work/s1/render" --slurm --wait \
  --poll 0.5 --quiet --json >"$work/s2b.json" 2>"$work/s2b.err"
grep -qF "earlier Slurm run: unit 1:" "$work/s2b.err" || die "case 2: re-run does not report the earlier failure"
[ "$(json_field "$work/s2b.json" submitted_units)" = "[1]" ] || die "case 2: re-run submitted more than unit 1"
same_as_local "$work/s2"

step "case 3: an array task killed while running is reported, the re-run completes only it"
"$HANDDB" generate "$work/config.json" --out "$work/s3" --slurm --max-parallel 2 --quiet --json \
  >"$work/s3.json"
array_id="$(json_field "$work/s3.json" array_job_ids | tr -d '[]" ')"
final_id="$(json_field "$work/s3.json" final_job_id | tr -d '"')"
log3="$work/s3/render/slurm/logs/u00002.log"
for _ in $(seq 1 600); do [ -s "$log3" ] && break; sleep 0.1; done
[ -s "$log3" ] || die "case 3: unit 2 never started"
scancel "${array_id}_2"
for _ in $(seq 1 600); do
  squeue -h -j "$array_id,$final_id" 2>/dev/null | grep -q . || break
  sleep 0.5
done
"$HANDDB" unit status "$work/s3/render" --out "$work/s3" >"$work/s3.status"
cat "$work/s3.status"
grep -q "^3 of 4 units complete; pending: 2$" "$work/s3.status" || die "case 3: status"
grep -q "^unit 2: .*CANCELLED.*; log: $log3$" "$work/s3.status" || die "case 3: no CANCELLED report for unit 2"
"$HANDDB" generate "$work/config.json" --out "$work/s3" --slurm --wait --poll 0.5 --quiet --json \
  >"$work/s3b.json" 2>/dev/null
[ "$(json_field "$work/s3b.json" submitted_units)" = "[2]" ] || die "case 3: re-run submitted more than unit 2"
same_as_local "$work/s3"

step "case 4: --index builds the search index in the final job, as a local --index does"
# Case 1's renders again (--work): the reference builds locally with 2 threads, the final job with
# the job's 1 CPU; the index must not depend on either.
"$HANDDB" generate "$work/config.json" --out "$work/local-idx" --work "$work/local/render" \
  --jobs 2 --index --quiet >/dev/null
idx="$(json_field "$work/local-idx/manifest.json" index | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["file"])')"
[ -s "$work/local-idx/$idx" ] || die "case 4: the local build lists no index file"
"$HANDDB" generate "$work/config.json" --out "$work/s4" --work "$work/s1/render" --slurm --index \
  --wait --poll 0.5 --quiet >/dev/null
grep -q 'unit finalize .* --index' "$work/s1/render/slurm/generate-final.sbatch" || die "case 4: no index in the final job"
for f in "$idx" manifest.json; do
  cmp "$work/local-idx/$f" "$work/s4/$f" || die "case 4: $f differs from the local --index build"
done
# A complete database without an index: --index submits the final job alone, which adds it.
"$HANDDB" generate "$work/config.json" --out "$work/s1" --slurm --index --wait --poll 0.5 --quiet \
  --json >"$work/s1i.json"
[ "$(json_field "$work/s1i.json" submitted_units)" = "[]" ] || die "case 4: re-run submitted units"
cmp "$work/local-idx/$idx" "$work/s1/$idx" || die "case 4: the index added to s1 differs"
"$HANDDB" validate "$work/s1" >/dev/null || die "case 4: s1 with its index does not validate"
echo "case 4: $idx identical locally, in the final job, and added to a complete database"

step "all Slurm cases passed"
