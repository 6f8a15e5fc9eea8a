#!/usr/bin/env bash
# Runs the libFuzzer targets for SECONDS in total (default 75), split evenly over the targets (at
# least 5 s each), so adding a target keeps the run short.
#   scripts/fuzz.sh [SECONDS] [BUILD_DIR]
# BUILD_DIR: a clang build configured with -DHANDDB_FUZZ=ON (scripts/test.sh passes its sanitizer
# build); without it, build-fuzz is configured with the fuzz targets and what they link only.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
total="${1:-75}"
build="${2:-}"
targets=()
for src in "$here"/tests/fuzz/*_fuzzer.cc; do targets+=("$(basename "${src%.cc}")"); done
if [ -z "$build" ]; then
  build="$here/build-fuzz"
  CC=clang CXX=clang++ cmake -S "$here" -B "$build" -G Ninja -DHANDDB_FUZZ=ON -DHANDDB_BUILD_TESTS=OFF \
    -DHANDDB_BUILD_BENCH=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_UNITY_BUILD=ON \
    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1" > "$build.cmake.log" 2>&1 \
    || { cat "$build.cmake.log"; exit 1; }
fi
cmake --build "$build" -j "$(nproc)" --target "${targets[@]}"
count=0
for target in "$build"/tests/fuzz/*_fuzzer; do [ -x "$target" ] && count=$((count + 1)); done
seconds=$(( count > 0 ? total / count : total ))
[ "$seconds" -ge 5 ] || seconds=5
found=0
for target in "$build"/tests/fuzz/*_fuzzer; do
  [ -x "$target" ] || continue
  found=1
  name="$(basename "$target")"
  corpus="$here/tests/fuzz/corpus/${name%_fuzzer}"
  work="$(mktemp -d)"
  echo "fuzz: $name for ${seconds}s"
  # A finding writes the input to $here/crash-* (or oom-/timeout-): show the report, not just stats.
  status=0
  ( cd "$here" && "$target" -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 \
      -print_final_stats=1 "$work" $( [ -d "$corpus" ] && echo "$corpus" ) ) > "$work.log" 2>&1 \
    || status=$?
  if [ "$status" != 0 ]; then
    grep -v '^#[0-9]' "$work.log" | tail -60
    echo "fuzz: $name failed (exit $status); the input is in $here as crash-*/oom-*/timeout-*" >&2
    rm -rf "$work" "$work.log"
    exit "$status"
  fi
  tail -5 "$work.log"
  rm -rf "$work" "$work.log"
done
[ "$found" = 1 ] || { echo "fuzz: no fuzz targets were built" >&2; exit 1; }
