#!/usr/bin/env bash
# The main job end to end on the embedded defaults, on a fresh Debian 12 machine (as root):
# install deps, build, generate a small database (configs/demo.json: render with Blender,
# convert to shards), validate it, render a held-out test view, query the database with it,
# and show the result (a table on the terminal and a contact sheet PNG).
#   scripts/demo.sh [OUT_DIR]      (default: ./demo-out)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$here/demo-out}"
cd "$here"
start=$(date +%s)
step() { echo; echo "=== demo: $* ($(( $(date +%s) - start ))s)"; }

step "dependencies"
scripts/deps.sh
step "build"
scripts/build.sh "$here/build" > "$here/build.log" 2>&1 || { tail -40 "$here/build.log"; exit 1; }
handdb="$here/build/cli/handdb"
mkdir -p "$out"

step "generate the demo database (configs/demo.json)"
"$handdb" generate configs/demo.json --out "$out/db"

step "validate"
"$handdb" validate "$out/db"
"$handdb" info "$out/db"

step "render held-out test views (configs/testset-demo.json)"
"$handdb" testset configs/testset-demo.json --out "$out/testset"

step "query the database with a held-out photo-like test image"
# The first held-out photo of a basic shape (the demo database holds 6 of them, on its grid of
# 42 directions x 12 rolls; the test view's direction and roll are off that grid).
query_image="$out/testset/$(/usr/bin/python3 -c 'import json,sys; t=json.load(open(sys.argv[1])); print(next(i["photo"] for i in t["items"] if i["basic"]))' "$out/testset/testset.json")"
"$handdb" query "$out/db" "$query_image" --top 5 --sheet "$out/query_sheet.png" --export "$out/pose.glb"
"$handdb" query "$out/db" "$query_image" --top 5 --json > "$out/query_result.json"

step "evaluate on the held-out test set"
"$handdb" evaluate "$out/db" "$out/testset" --input clean --json "$out/evaluation.json"

step "done"
echo "database:      $out/db"
echo "query image:   $query_image"
echo "contact sheet: $out/query_sheet.png"
echo "result JSON:   $out/query_result.json"
echo "fitted pose:   $out/pose.glb (glTF: open in Blender or a web viewer)"
