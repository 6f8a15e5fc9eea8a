#!/usr/bin/env bash
# install/consumer_test: the installed package works from outside this repository.
#   consumer_test.sh BUILD_DIR THIS_DIR WRITE_TEST_DATABASE HANDDB_PYTHON PYTHON3 PYTHON_SITE
# 1. `cmake --install BUILD_DIR --prefix TMP/prefix`; the layout: binary, archives, door headers
#    only, schemas, config files, Python package.
# 2. A small database (write_test_database) and an edge image of view 5 at roll 3 drawn by the
#    installed `handdb show`.
# 3. consumer/ configured with find_package(handdb) against the prefix and built: the README's
#    "From C++" program (extracted from README.md) and every installed header in one unit. The
#    program's top match must be view 5 roll 3; the installed Python module must print the same.
set -euo pipefail
build="$1"; here="$2"; writer="$3"; with_python="$4"; python="${5:-/usr/bin/python3}"; site="${6:-}"
tmp="$(mktemp -d /tmp/handdb-install-test.XXXXXX)"
trap 'rm -rf "$tmp"' EXIT
prefix="$tmp/prefix"
fail() { echo "install/consumer_test: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" > "$tmp/install.log" || { cat "$tmp/install.log"; fail "cmake --install failed"; }
for f in bin/handdb lib/libhanddb_format.a lib/libhanddb_query.a lib/cmake/handdb/handdbConfig.cmake \
         lib/cmake/handdb/handdbConfigVersion.cmake lib/cmake/handdb/handdbTargets.cmake \
         include/handdb/query/searcher.h include/handdb/format/shard_reader.h \
         include/handdb/handdb_version.h share/handdb/schemas/manifest.schema.json; do
  [ -f "$prefix/$f" ] || fail "$prefix/$f: not installed"
done
# handdb's plugins (base/plugin.h), opened on first use, beside the binary and the Python module.
plugins="libhanddb_fit.so libhanddb_pcl_kdtree.so"
for p in $plugins; do
  [ -f "$prefix/bin/$p" ] || fail "$prefix/bin/$p: the plugin was not installed beside the binary"
  if [ "$with_python" = "ON" ]; then
    [ -f "$prefix/$site/handdb/$p" ] || fail "$prefix/$site/handdb/$p: the plugin was not installed beside the Python module"
  fi
done
# Internals stay out of the installed tree.
for f in format/shard_layout.h format/shard_testing.h query/chamfer.h query/simd.h \
         query/search_testing.h base/testing.h edges/synthetic_hand.h; do
  [ ! -e "$prefix/include/handdb/$f" ] || fail "$prefix/include/handdb/$f: an internal header was installed"
done
echo "installed: $(find "$prefix/include" -name '*.h' | wc -l) headers, $(ls "$prefix/lib"/*.a | wc -l) archives"

"$writer" "$tmp/db" > /dev/null
"$prefix/bin/handdb" validate -q "$tmp/db"
"$prefix/bin/handdb" show "$tmp/db" --view 5 --roll 3 -o "$tmp/query.png"
# The installed binary opens the installed plugin (the first place it looks: beside itself).
LD_DEBUG=files "$prefix/bin/handdb" query "$tmp/db" "$tmp/query.png" --kdtree pcl -q \
  > /dev/null 2> "$tmp/ld.log" || { tail -5 "$tmp/ld.log"; fail "handdb query --kdtree pcl failed"; }
grep -q "file=$prefix/bin/libhanddb_pcl_kdtree.so " "$tmp/ld.log" \
  || fail "the installed handdb did not open $prefix/bin/libhanddb_pcl_kdtree.so"

readme="${HANDDB_SOURCE_DIR:-$here/../..}/README.md"
awk '/^## From C\+\+/ { section = 1 } section && /^```cpp/ { code = 1; next } code && /^```/ { exit } code' \
  "$readme" > "$tmp/top_match.cc"
grep -q "int main" "$tmp/top_match.cc" || fail "$readme: no C++ program under '## From C++'"
cmake -S "$here/consumer" -B "$tmp/consumer" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" \
  -DCMAKE_BUILD_TYPE=Release -DTOP_MATCH_SOURCE="$tmp/top_match.cc" > "$tmp/configure.log" 2>&1 || { cat "$tmp/configure.log"; fail "configuring the consumer failed"; }
cmake --build "$tmp/consumer" > "$tmp/build.log" 2>&1 || { cat "$tmp/build.log"; fail "building the consumer failed"; }
out="$("$tmp/consumer/top_match" "$tmp/db" "$tmp/query.png")"
echo "top_match: $out"
# Rank 1 is the drawn view (D_c is not 0: the drawing is rasterised and normalised again).
[[ "$out" =~ ^"top match: view 5 roll 3 D_c "[0-9.]+" shape fist"$ ]] || fail "top_match printed '$out', expected view 5 roll 3 (fist) first"
expected="$out"

if [ "$with_python" = "ON" ]; then
  [ -f "$prefix/$site/handdb/__init__.py" ] || fail "$prefix/$site/handdb: the Python package was not installed"
  py_out="$(cd "$tmp" && PYTHONPATH="$prefix/$site" "$python" -c '
import sys, handdb
assert handdb.__file__.startswith(sys.argv[1]), handdb.__file__
m = handdb.Database(sys.argv[2]).search(sys.argv[3], top_k=3, hand="right")[0]
print("top match: view %d roll %d D_c %.3f shape %s" % (m.view_id, m.roll, m.distance, m.shape_name))
' "$prefix" "$tmp/db" "$tmp/query.png")"
  echo "python:   $py_out"
  [ "$py_out" = "$expected" ] || fail "the installed Python module printed '$py_out', expected '$expected'"
fi
echo "install/consumer_test: ok"
