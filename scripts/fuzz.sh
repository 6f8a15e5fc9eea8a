#!/usr/bin/env bash
# Builds the libFuzzer targets with clang and runs them for SECONDS in total (default 75), split
# evenly over the targets (at least 10 s each), so adding a target keeps the run short.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
total="${1:-75}"
build="$here/build-fuzz"
# Only the fuzz targets and what they link (the format library): a whole clang build would
# cost CI minutes for nothing.
targets=()
for src in "$here"/tests/fuzz/*_fuzzer.cc; do targets+=("$(basename "${src%.cc}")"); done
CC=clang CXX=clang++ cmake -S "$here" -B "$build" -G Ninja -DHANDDB_FUZZ=ON -DHANDDB_BUILD_TESTS=OFF \
  -DHANDDB_BUILD_BENCH=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo > "$build.cmake.log" 2>&1 \
  || { cat "$build.cmake.log"; exit 1; }
cmake --build "$build" -j "$(nproc)" --target "${targets[@]}"
count=0
for target in "$build"/tests/fuzz/*_fuzzer; do [ -x "$target" ] && count=$((count + 1)); done
seconds=$(( count > 0 ? total / count : total ))
[ "$seconds" -ge 10 ] || seconds=10
found=0
for target in "$build"/tests/fuzz/*_fuzzer; do
  [ -x "$target" ] || continue
  found=1
  name="$(basename "$target")"
  corpus="$here/tests/fuzz/corpus/${name%_fuzzer}"
  work="$(mktemp -d)"
  echo "fuzz: $name for ${seconds}s"
  "$target" -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 "$work" \
    $( [ -d "$corpus" ] && echo "$corpus" ) 2>&1 | tail -5
  rm -rf "$work"
done
[ "$found" = 1 ] || { echo "fuzz: no fuzz targets were built" >&2; exit 1; }
