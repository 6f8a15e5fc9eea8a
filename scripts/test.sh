#!/usr/bin/env bash
# Runs every test on a fresh Debian machine: installs deps, builds (warnings as errors), runs
# the C++ tests (CTest), the Python tests (pytest, Debian's python3), then the C++ tests again
# under ASan+UBSan (clang) and a short libFuzzer run of every parser, from one clang build.
#   scripts/test.sh            # everything
#   HANDDB_TEST_QUICK=1 scripts/test.sh   # skip the sanitizer build and the fuzz run
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
jobs="$(nproc)"
start=$(date +%s)
step() { echo; echo "=== test.sh: $* ($(( $(date +%s) - start ))s)"; }

step "dependencies"
scripts/deps.sh

step "build (Release with debug info, -Werror)"
# -g1 (line tables: stack traces keep files and lines) instead of -g: 16% less compile time.
# Without bench/ (HANDDB_BUILD_BENCH=OFF; every other build compiles it, bench/run.sh runs it): its
# programs are ~110 s of this build and no test runs them, and CI's budget is 30 minutes.
scripts/build.sh "$here/build" -DHANDDB_WERROR=ON -DHANDDB_BUILD_BENCH=OFF \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"

step "C++ tests"
(cd build && ctest --output-on-failure -j "$jobs" --timeout 900)

step "Python tests (Debian python3)"
# tests/python/ includes the handdb module's tests, against the module and the binary
# of this build; a missing module fails them instead of skipping. On every core (pytest-xdist):
# the Blender tests wait on Blender's start-up half of the time.
PYTHONPATH="$here/build/python" HANDDB_BINARY_DIR="$here/build" HANDDB_REQUIRE_PYTHON_MODULE=1 \
  /usr/bin/python3 -m pytest -q -n "$jobs" blender_scripts tests/python

if [ "${HANDDB_TEST_QUICK:-0}" != 1 ]; then
  # One clang build for the sanitizer tests and the fuzz targets (a second build of the whole tree
  # cost CI five minutes). -O0 -g1 (the search and edge libraries at -O1, see CMakeLists.txt):
  # ASan+UBSan at -O1 doubles the compile time of our template-heavy files, and -O0 alone makes the
  # search tests 3x slower; stack traces keep files and lines. libFuzzer's coverage instrumentation
  # is in the parsers only. The integration tests (whole searches and evaluations over databases,
  # already run above) are neither built nor run: under the sanitizers they cost minutes and reach
  # the same code the unit tests reach. The hardening test (hostile inputs through the CLI) stays
  # in. The Python module is not built: pytest runs on the build above.
  step "build with clang, ASan+UBSan and the fuzz targets"
  scripts/build.sh "$here/build-asan" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
    -DHANDDB_WERROR=ON -DHANDDB_SANITIZE=ON -DHANDDB_FUZZ=ON -DHANDDB_BUILD_BENCH=OFF -DHANDDB_INTEGRATION_TESTS=OFF -DHANDDB_PYTHON=OFF \
    -DCMAKE_BUILD_TYPE=Debug "-DCMAKE_CXX_FLAGS_DEBUG=-O0 -g1" "-DCMAKE_C_FLAGS_DEBUG=-O0 -g1"
  step "C++ tests under ASan+UBSan (all but integration)"
  (cd build-asan && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --output-on-failure -j "$jobs" --timeout 1800 -LE "no_sanitizer|integration")

  step "fuzz targets (short libFuzzer runs)"
  scripts/fuzz.sh 60 "$here/build-asan"
fi
step "all tests passed"
