#!/usr/bin/env bash
# Builds the libFuzzer targets with clang and runs each for SECONDS (default 60).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds="${1:-60}"
build="$here/build-fuzz"
CC=clang CXX=clang++ scripts/build.sh "$build" -DHANDDB_FUZZ=ON -DHANDDB_BUILD_TESTS=OFF -DHANDDB_BUILD_BENCH=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo > /dev/null
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
[ "$found" = 1 ] || echo "fuzz: no fuzz targets built"
