#!/usr/bin/env bash
# Configures and builds handdb.  scripts/build.sh [BUILD_DIR] [extra cmake args...]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$here/build}"
shift || true
cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "$@" > "$build.cmake.log" 2>&1 \
  || { mkdir -p "$build"; cat "$build.cmake.log"; exit 1; }
cmake --build "$build" -j "$(nproc)"
