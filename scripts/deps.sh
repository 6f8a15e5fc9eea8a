#!/usr/bin/env bash
# Installs everything handdb needs on a fresh Debian 12 machine (as root), idempotently:
# Debian packages, and from the npm registry (pinned versions + sha256) the default hand asset
# and the hand landmark model.
#   scripts/deps.sh            # packages + assets
#   scripts/deps.sh --asset    # only the assets
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

PACKAGES=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  blender python3-numpy python3-pytest python3-pytest-xdist python3-opencv python3-jsonschema
  openimageio-tools libopenexr-dev libopencv-dev libeigen3-dev
  libpcl-dev libnanoflann-dev libcli11-dev nlohmann-json3-dev libzstd-dev libxxhash-dev
  nettle-dev libboost-dev libfaiss-dev libpng-dev libjpeg62-turbo-dev libceres-dev
  # xnnpack.h includes pthreadpool.h, which libxnnpack-dev does not pull in.
  libxnnpack-dev libpthreadpool-dev libtinygltf-dev
  python3-dev pybind11-dev python3-pybind11
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev clang-format clang-tidy
  slurm-wlm munge xxhash
)
# npm may come from elsewhere on the machine (it does on these images); Debian's only if absent.
command -v npm > /dev/null 2>&1 || PACKAGES+=(npm)

install_packages() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    echo "deps: all ${#PACKAGES[@]} Debian packages present"
    return
  fi
  echo "deps: installing ${#missing[@]} Debian packages: ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" \
    > /tmp/handdb-apt.log 2>&1 || { tail -30 /tmp/handdb-apt.log; echo "deps: apt-get install failed (log: /tmp/handdb-apt.log)" >&2; exit 1; }
}

# The default hand: WebXR generic hand, MIT licence (see third_party/README.md).
ASSET_PACKAGE="@webxr-input-profiles/assets"
ASSET_VERSION="1.0.20"
ASSET_TGZ_SHA256="30df2a2268220fc0d0e034bed1550aabdd7a2500573c5216f64fc70d59c3d91e"
ASSET_GLB_SHA256="291790c14f7f88a7f9bd35330c47392ed8e8d395ae6728f4bb7089f1bc1f2b96"
ASSET_DIR="${HANDDB_ASSET_DIR:-$here/third_party/assets}"

# npm_file PACKAGE VERSION TGZ_SHA256 FILE FILE_SHA256 DEST_DIR [EXTRA...]: the package's FILE
# (a path inside the tarball's package/) installed as DEST_DIR/<its name>, after both checksums;
# EXTRA files of the package (licence, package.json) copied beside it. Nothing is fetched when
# the installed file already has its checksum.
npm_file() {
  local package="$1" version="$2" tgz_sha="$3" file="$4" file_sha="$5" dest_dir="$6"
  shift 6
  local dest
  dest="$dest_dir/$(basename "$file")"
  if [ -f "$dest" ] && echo "$file_sha  $dest" | sha256sum -c --status; then
    echo "deps: $package $(basename "$file") present ($dest)"
    return
  fi
  command -v npm > /dev/null || { echo "deps: npm is missing (install the nodejs/npm packages)" >&2; exit 1; }
  local tmp
  tmp="$(mktemp -d)"
  trap 'rm -rf "$tmp"; trap - RETURN' RETURN
  echo "deps: fetching $package@$version from the npm registry"
  (cd "$tmp" && npm pack --silent "$package@$version" > /dev/null)
  # npm pack names the tarball after the package: @scope/name -> scope-name-VERSION.tgz.
  local tgz
  tgz="$tmp/$(echo "${package#@}" | tr / -)-$version.tgz"
  echo "$tgz_sha  $tgz" | sha256sum -c --status || {
    echo "deps: $tgz: sha256 mismatch (expected $tgz_sha, got $(sha256sum "$tgz" | cut -d' ' -f1))" >&2
    exit 1
  }
  local extra=()
  for e in "$@"; do extra+=("package/$e"); done
  tar -xzf "$tgz" -C "$tmp" "package/$file" "${extra[@]}"
  echo "$file_sha  $tmp/package/$file" | sha256sum -c --status || {
    echo "deps: $(basename "$file"): sha256 mismatch" >&2
    exit 1
  }
  mkdir -p "$dest_dir"
  # Readable by every user (the npm tarballs carry modes like 0750 and 0440).
  for e in "$@"; do install -m 0644 "$tmp/package/$e" "$dest_dir/$(basename "$e")"; done
  install -m 0644 "$tmp/package/$file" "$dest.tmp" && sync "$dest.tmp" && mv "$dest.tmp" "$dest"
  echo "deps: installed $dest (sha256 $file_sha)"
}

install_asset() {
  npm_file "$ASSET_PACKAGE" "$ASSET_VERSION" "$ASSET_TGZ_SHA256" \
    dist/profiles/generic-hand/right.glb "$ASSET_GLB_SHA256" "$ASSET_DIR/generic-hand" \
    LICENSE.md package.json
}

# The hand landmark network the photo path runs (photo/hand_landmarks.h): MediaPipe
# Hands' hand_landmark_full.tflite, Apache-2.0 (see third_party/README.md).
LANDMARK_PACKAGE="@mediapipe/hands"
LANDMARK_VERSION="0.4.1675469240"
LANDMARK_TGZ_SHA256="bdd5be939c60cbd72a49f4b6141407683cf2a67263598e1a44757d70b3dfcb8a"
LANDMARK_MODEL_SHA256="8c026882c9ec059ce0f8e75266bee5a9a23c341a40e0000df755374d3d1b9b68"

install_landmark_model() {
  npm_file "$LANDMARK_PACKAGE" "$LANDMARK_VERSION" "$LANDMARK_TGZ_SHA256" \
    hand_landmark_full.tflite "$LANDMARK_MODEL_SHA256" "$ASSET_DIR/mediapipe-hands" package.json
}

case "${1:-}" in
  --asset) install_asset; install_landmark_model ;;
  "") install_packages; install_asset; install_landmark_model ;;
  *) echo "usage: scripts/deps.sh [--asset]" >&2; exit 2 ;;
esac
