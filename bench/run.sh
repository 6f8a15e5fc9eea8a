#!/usr/bin/env bash
# Runs every benchmark of handdb on this machine and writes a generated, dated report:
#   bench/results.json                  every number (and each benchmark's own output)
#   docs/results/DATE-NAME.md           the machine, the numbers, the ratios against the in-run
#                                       baselines; DATE is today's (UTC), NAME is
#                                       $HANDDB_BENCH_NAME (default "<cores>-core")
#   docs/results/DATE-NAME/             pictures of successes and failures, the scaling plot
# A run never writes into a hand-written page: docs/results.md explains the benchmarks and links
# the reports.
#
#   bench/run.sh                          # format, render, convert, query, evaluate (paper database)
#   HANDDB_BENCH_PCA_LARGE=1 bench/run.sh # also the pca-large database (1,056,768 virtual views)
#   HANDDB_BENCH_DIR=/data/bench bench/run.sh
#
# Steps (each one's stdout/stderr and wall time go to $HANDDB_BENCH_DIR/out/):
#   build     Release build of handdb and the bench programs (build-bench/)
#   format    bench/format_bench: shard write / scan / validate vs raw read() of the same bytes
#   landmark  bench/landmark_bench on one core: the landmark network on the portable kernels and
#             on XNNPACK, load + first run (fresh processes) and warm run
#   render    bench/render_bench.py: Blender renders/s vs one bare Blender start
#   generate  handdb generate configs/paper.json (26 shapes x 86 directions x 48 rolls)
#   convert   bench/convert_bench on the paper renders: views/s with 1 and 2 threads
#   testset   handdb testset configs/testset-paper.json (plain photos) and --clutter
#   query     bench/query_bench on the paper database: pruned vs brute force vs naive PCL, then
#             the query sets users send: real photos, the test set's photo-like and
#             clean label renders, the perturbed views; latency median/p90/max with --hand either
#             and right, share refined, brute force on 3 of each (after testset: it reads ts-paper)
#   picture   bench/picture_bench on the paper database and the real photos: start-up, each stage
#             of a photo cold and warm, photos/s of a batch against one process per photo
#   startup   bench/startup_bench: handdb --help against /bin/true (shared objects, relocations),
#             one photo through handdb query against its warm search; HANDDB_BENCH_BASELINE=BINARY
#             alternates another handdb build run by run
#   evaluate  handdb evaluate: clean labels, plain photos, cluttered photos (Table 1,
#             success@(d,n) with the chance baseline, keypoint error, queries/s)
#   photos    handdb evaluate --photos: the real-photo development set (../shared/photos/asl-digits)
#             against the paper database: top-1/5/10 shape accuracy, chance, confusion matrix;
#             the defaults (either hand, shapes ranked, hand landmarks), then --hand right,
#             --rank views and --landmarks off (the in-run baseline of the landmark re-ranking)
#   index     handdb index on the paper database, then bench/index_bench: indexed search against
#             exact search on the same query sets (latency, recall@1/10, candidates refined)
#   codec     bench/point_codec_bench on the paper database: the point and coarse-field codes'
#             bytes per view, decode time, and the storage per virtual view they give
#   scale     (HANDDB_BENCH_SCALE=1) the scaling runs: bench/synth_db makes 10M and 50M
#             virtual views from pca-large (or the paper database when pca-large is not built),
#             handdb index, index_bench on each (fewer queries at 50M: exact search takes
#             seconds there), the 10M one again with coded shards (synth_db --coded, format
#             v1.2), and bench/plot_scaling.py draws latency against size
#   report    bench/report.py -> bench/results.json, docs/results/DATE-NAME.md
# Databases and test sets are kept in $HANDDB_BENCH_DIR (default /tmp/handdb-bench) and reused by
# a rerun (generate and testset resume); the benchmarks themselves always run again.
# HANDDB_BENCH_FRESH=1 removes the databases and test sets first (renders included).
# HANDDB_BENCH_STEPS="evaluate report" runs only some steps (the others' outputs are reused); the
# pca-large steps are named pca_large_generate, pca_large_query and pca_large_evaluate.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
work="${HANDDB_BENCH_DIR:-/tmp/handdb-bench}"
build="${HANDDB_BENCH_BUILD:-$here/build-bench}"
jobs="${HANDDB_BENCH_JOBS:-$(nproc)}"
steps="${HANDDB_BENCH_STEPS:-build format landmark render generate convert query picture startup testset evaluate photos index codec report}"
if [ "${HANDDB_BENCH_PCA_LARGE:-0}" = 1 ] && [ -z "${HANDDB_BENCH_STEPS:-}" ]; then
  steps="$steps pca_large_generate pca_large_query pca_large_evaluate"
fi
if [ "${HANDDB_BENCH_SCALE:-0}" = 1 ] && [ -z "${HANDDB_BENCH_STEPS:-}" ]; then
  steps="${steps/ report/} scale report"
fi
out="$work/out"
report="docs/results/$(date -u +%F)-${HANDDB_BENCH_NAME:-$(nproc)-core}"
if [ "${HANDDB_BENCH_FRESH:-0}" = 1 ]; then
  rm -rf "$work/db-paper" "$work/db-pca-large" "$work/ts-paper" "$work/ts-paper-clutter" "$out" \
    "$work/plots"
fi
mkdir -p "$out"
start=$(date +%s)
handdb="$build/cli/handdb"
photos="${HANDDB_BENCH_PHOTOS:-$here/../shared/photos/asl-digits}"

want() { [[ " $steps " == *" $1 "* ]]; }
log() { echo "=== bench/run.sh: $* ($(($(date +%s) - start)) s)" >&2; }

# run NAME CMD...: stdout -> out/NAME.txt, stderr -> out/NAME.err, wall time + exit code -> out/NAME.time
run() {
  local name="$1"
  shift
  log "$name: $*"
  local t0 t1 rc=0
  t0=$(date +%s.%N)
  "$@" >"$out/$name.txt" 2>"$out/$name.err" || rc=$?
  t1=$(date +%s.%N)
  printf '{"seconds": %.3f, "exit_code": %d, "command": "%s"}\n' \
    "$(awk "BEGIN { print $t1 - $t0 }")" "$rc" "$*" >"$out/$name.time"
  if [ "$rc" -ne 0 ]; then
    log "$name failed (exit $rc): $(tail -n 3 "$out/$name.err" | tr '\n' ' ')"
  fi
  return 0
}

if want build; then
  log "build (Release) into $build"
  cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DHANDDB_BUILD_TESTS=OFF \
    >"$out/build.txt" 2>&1
  cmake --build "$build" -j "$jobs" --target handdb format_bench convert_bench query_bench \
    index_bench synth_db point_codec_bench landmark_bench picture_bench startup_bench \
    >>"$out/build.txt" 2>&1
fi

if want format; then
  run format "$build/bench/format_bench" --dir "$work"
fi

if want landmark; then
  run landmark taskset -c 0 "$build/bench/landmark_bench"
fi

if want render; then
  # 6 shapes x 86 directions (516 renders) in 4 units: long enough for a stable rate.
  run render /usr/bin/python3 bench/render_bench.py --shapes 6 --dirs 86 --unit-size 129 \
    --jobs "$jobs" --json
fi

if want generate; then
  run generate_paper "$handdb" generate configs/paper.json -o "$work/db-paper" -j "$jobs" -q --json
fi

if want convert; then
  run convert "$build/bench/convert_bench" --render-dir "$work/db-paper/render"
fi

if want testset; then
  run testset_paper "$handdb" testset configs/testset-paper.json --out "$work/ts-paper" \
    -j "$jobs" -q --json
  run testset_paper_clutter "$handdb" testset configs/testset-paper.json --clutter \
    --out "$work/ts-paper-clutter" -j "$jobs" -q --json
fi

# query_bench's test-set query sets: skipped (with a note in its output) when ts-paper is missing.
sets=(--photos "$photos")
if [ -f "$work/ts-paper/testset.json" ]; then sets+=(--testset "$work/ts-paper"); fi
if want query; then
  # 20 queries per set (--set-queries), spread over the photo folders and the test views.
  run query "$build/bench/query_bench" --db "$work/db-paper" --threads "$jobs" "${sets[@]}" \
    --set-queries 20
fi

if want picture; then
  # 24 photos spread over the folders: the stages of one, then batch against one process each.
  run picture "$build/bench/picture_bench" --db "$work/db-paper" --photos "$photos" \
    --threads "$jobs" --handdb "$handdb"
fi

if want startup; then
  # The start and one photo (the first in sorted order), each against its baseline in the run.
  run startup "$build/bench/startup_bench" --handdb "$handdb" --db "$work/db-paper" \
    --photo "$(find "$photos" -type f -iname '*.jpg' | sort | head -n 1)" --threads "$jobs" \
    ${HANDDB_BENCH_BASELINE:+--baseline "$HANDDB_BENCH_BASELINE"}
fi

evaluate() {  # NAME DB TESTSET INPUT [extra evaluate options]
  local name="$1" db="$2" ts="$3" input="$4"
  shift 4
  run "eval_$name" "$handdb" evaluate "$db" "$ts" --input "$input" --threads "$jobs" \
    --json "$out/eval_$name.json" --plots "$work/plots/$name" "$@"
}
if want evaluate; then
  evaluate paper_clean "$work/db-paper" "$work/ts-paper" clean
  evaluate paper_photo "$work/db-paper" "$work/ts-paper" photo
  evaluate paper_clutter "$work/db-paper" "$work/ts-paper-clutter" photo
fi

if want photos; then
  # The defaults users get (--hand either: each photo and its mirror image; --rank shapes: top-k
  # over the k nearest shapes), which the photo accuracy targets are stated for; then --hand right
  # (the development photos are right hands) and --rank views (top-k over the k nearest views,
  # the count before shapes were ranked), each against the same database.
  run eval_photos "$handdb" evaluate "$work/db-paper" --photos "$photos" \
    --threads "$jobs" --json "$out/eval_photos.json" --out "$work/plots/photos"
  run eval_photos_right "$handdb" evaluate "$work/db-paper" --photos "$photos" --hand right \
    --threads "$jobs" --json "$out/eval_photos_right.json"
  run eval_photos_views "$handdb" evaluate "$work/db-paper" --photos "$photos" --rank views \
    --threads "$jobs" --json "$out/eval_photos_views.json"
  # The in-run baseline of the landmark re-ranking (docs/photo.md, "Hand landmarks"): D_c alone.
  # Its timing against eval_photos' is the cost of the landmarks (network + pool search).
  run eval_photos_no_landmarks "$handdb" evaluate "$work/db-paper" --photos "$photos" \
    --landmarks off --threads "$jobs" --json "$out/eval_photos_no_landmarks.json"
fi

if want pca_large_generate; then
  run generate_pca_large "$handdb" generate configs/pca-large.json -o "$work/db-pca-large" \
    -j "$jobs" -q --json
fi
if want pca_large_query; then
  # Latency and memory at 1M virtual views; no brute force (~5 min per query here). The query
  # sets with 8 queries each: a real photo's exact search takes much longer than at 100k views.
  run query_pca_large "$build/bench/query_bench" --db "$work/db-pca-large" --threads "$jobs" \
    --queries 5 --brute-queries 0 --baseline-fraction 0.001 "${sets[@]}" --set-queries 8
fi
if want pca_large_evaluate; then
  # Every 4th test view (50: 25 basic-shape, 25 PCA): a query is ~10x slower than on the paper
  # database; HANDDB_BENCH_PCA_STRIDE=1 evaluates all 200.
  stride="${HANDDB_BENCH_PCA_STRIDE:-4}"
  evaluate pca_large_clean "$work/db-pca-large" "$work/ts-paper" clean --stride "$stride"
  evaluate pca_large_photo "$work/db-pca-large" "$work/ts-paper" photo --stride "$stride"
fi

if want index; then
  run index_paper "$handdb" index "$work/db-paper" -j "$jobs" -q
  run index_bench_paper "$build/bench/index_bench" --db "$work/db-paper" --threads "$jobs" \
    "${sets[@]}" --set-queries 20 --perturbed 10 --candidates 500,1000
fi

if want codec; then
  run point_codec_paper "$build/bench/point_codec_bench" --db "$work/db-paper"
fi

if want scale; then
  # Synthetic 10M and 50M virtual views (bench/synth_db: near-copies of a real database's views),
  # each indexed and measured; exact results are cached beside the database, so a rerun times the
  # indexed search only once more and reuses the exact answers.
  src="$work/db-pca-large"
  [ -f "$src/manifest.json" ] || src="$work/db-paper"
  rolls=$(/usr/bin/python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['rolls'])" \
    "$src/manifest.json")
  for size in 10 50; do
    db="$work/db-synth-${size}m"
    if [ ! -f "$db/manifest.json" ]; then
      run synth_${size}m "$build/bench/synth_db" --from "$src" --out "$db" \
        --views $(((size * 1000000 + rolls - 1) / rolls)) --threads "$jobs"
      run index_synth_${size}m "$handdb" index "$db" -j "$jobs" -q
    fi
    queries=(--set-queries 20 --perturbed 10)
    [ "$size" = 50 ] && queries=(--set-queries 10 --perturbed 5)
    run index_bench_synth_${size}m "$build/bench/index_bench" --db "$db" --threads "$jobs" \
      "${sets[@]}" "${queries[@]}" --candidates 500,1000 --cache "$db/exact-cache.txt"
  done
  # The same 10M database coded (format v1.2, docs/format.md section 10): bytes per virtual view,
  # indexed latency, recall and peak memory of the coded shards.
  db="$work/db-synth-10m-coded"
  if [ ! -f "$db/manifest.json" ]; then
    run synth_10m_coded "$build/bench/synth_db" --from "$src" --out "$db" \
      --views $(((10000000 + rolls - 1) / rolls)) --threads "$jobs" --coded
    run index_synth_10m_coded "$handdb" index "$db" -j "$jobs" -q
  fi
  run index_bench_synth_10m_coded "$build/bench/index_bench" --db "$db" --threads "$jobs" \
    "${sets[@]}" --set-queries 20 --perturbed 10 --candidates 1000 --cache "$db/exact-cache.txt"
  mkdir -p "$report"
  inputs=("$out/index_bench_paper.txt")
  for size in 10 50; do inputs+=("$out/index_bench_synth_${size}m.txt"); done
  run plot_scaling /usr/bin/python3 bench/plot_scaling.py --candidates 1000 "$report/latency_vs_size.png" \
    "${inputs[@]}"
fi

if want report; then
  log "report"
  /usr/bin/python3 bench/report.py --work "$work" --handdb "$handdb" \
    --results bench/results.json --markdown "$report.md" --images "$report" \
    --name "${HANDDB_BENCH_NAME:-$(nproc)-core}"
fi
log "done"
